"""The engine's limits, one definition each: the settings models, the command line and the engine read them here.

At the bottom of the package beside :mod:`vibsynth.errors` (it imports nothing), so that the
typed settings (which may not import the engine), the engine and the adapters share each
number instead of writing it twice: a lab configured within its model's range plays, and a
value the engine refuses is refused where the config is loaded (``tests/test_limits.py``
walks every model range that feeds the engine).
"""

from __future__ import annotations

__all__ = [
    "MAX_CHANNELS",
    "VOICE_GAIN_MAX",
    "VOICE_GLIDE_MAX_S",
    "SCHEDULE_CAPACITY_MAX",
    "BANK_LEVELS_MAX",
    "GLIDE_MAX_MS",
    "ENGINE_RAMP_MAX_S",
    "CLIP_GAIN_MAX",
    "CLIP_RATE_MIN",
    "CLIP_RATE_MAX",
    "CLIP_LOOPS_MAX",
    "ACTUATOR_BOOST_MAX_DB",
    "OSC_FAST_ADDRESS_MAX",
    "OSC_PREFIX_MAX",
]

#: Output channels the engine renders (``MAXCH`` in ``engine/_core.c``): ``audio.channels``.
MAX_CHANNELS = 64
#: Largest linear gain of a buffer voice (a lab stimulus at its intensity-equalisation gain:
#: ``lab.gain_min``/``lab.gain_max``).
VOICE_GAIN_MAX = 16
#: Longest glide of a voice's gain change (s).
VOICE_GLIDE_MAX_S = 10.0
#: Most timetagged commands that may wait in the engine's scheduler (``knobs.schedule_capacity``).
SCHEDULE_CAPACITY_MAX = 1_000_000
#: Most noise-bank levels the engine crossfades between (``bank.levels`` allows fewer).
BANK_LEVELS_MAX = 4096
#: Longest knob glide (ms): ``knobs.glide_ms``, and every glide a control asks for.
GLIDE_MAX_MS = 10_000
#: Longest glide or mute fade the compiled core accepts at all (``MAX_GLIDE_S`` in
#: ``engine/_core.c``): the ``Engine`` refuses longer ones with a ParameterError before the core
#: would with a ValueError (``tests/test_limits.py`` checks the built core agrees).
ENGINE_RAMP_MAX_S = 3600.0
#: Clip playback (``/vibsynth/play``, ``vibsynth clip play``, ``midi_clips.notes``): largest gain
#: (intensity x gain is clamped to 1 anyway), rate range (time stretch; 1 = as designed), and
#: most loop passes one play may ask for (0 = until stopped).
CLIP_GAIN_MAX = 4.0
CLIP_RATE_MIN, CLIP_RATE_MAX = 0.05, 20.0
CLIP_LOOPS_MAX = 10_000
#: Largest boost the actuator compensation may be allowed (``actuator.max_boost_db``), in dB above
#: the response's level in the intensity band: a measured voice coil is ~30 dB down at 10 Hz.
ACTUATOR_BOOST_MAX_DB = 60.0
#: Longest address (bytes) the compiled OSC fast path's table holds (``MAX_ADDR - 1`` in
#: ``control/osc/_fast.c``; ``tests/control/osc/test_fast.py`` checks the built extension agrees).
OSC_FAST_ADDRESS_MAX = 127
#: Longest ``osc.prefix``: its longest fast-path address, ``{prefix}/ch/64/intensity`` at
#: :data:`MAX_CHANNELS` (intensity is the longest of the fast methods), fits the table.
OSC_PREFIX_MAX = OSC_FAST_ADDRESS_MAX - len(f"/ch/{MAX_CHANNELS}/intensity")
