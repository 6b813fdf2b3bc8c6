"""The real-time engine: knobs with glide, bank crossfade, gain, mute, limiter.

``Engine.render(frames) -> float32 [frames, channels]`` works without any audio
device; outputs call :meth:`Engine.render_into` from their audio thread.

Per channel and per sample:

1. **Knobs** (intensity 0..1, balance, mute gain 0..1) follow *linear* ramps: a
   move to ``target`` with glide ``T`` reaches it exactly ``round(T * fs)`` samples
   later (0 = jump on that very sample). A new move mid-glide starts from the
   current value. Ramps are computed from integer sample counts, so the values do
   not depend on how the stream is cut into blocks.
2. **Gain** from the intensity knob ``k``: band level
   ``ceiling_db - range_db * (1 - k)`` (the bank is at 0 dB band level), i.e.
   ``exp(a k + b)``, times ``min(1, k / 0.01)`` so that ``k -> 0`` fades to true
   silence without a step (only knobs below 0.01 are affected).
3. **Crossfade**: balance -> fractional bank position ``p``; the sample is
   ``(1 - f) x_i[n] + f x_{i+1}[n]`` with ``i = floor(p)``, ``f = p - i``. All levels
   share one phase spectrum (see :mod:`vibsynth.engine.bank`), so this is a
   magnitude crossfade: no power dip, no grain change.
4. **Safety limiter**: the bank's per-level peaks are known, and ``|x| <=
   (1-f) peak_i + f peak_{i+1}``, so the gain is capped at
   ``limiter_ceiling / that bound``: the output can never exceed the ceiling, and
   the cap is a smooth function of the (smoothed) balance, so it never distorts or
   clicks (it acts like a gain reduction that tracks the balance knob). A final
   hard clip at the ceiling guards against float rounding and never engages in
   practice.
5. **Mute/panic**: mute is a third ramped gain (``mute_fade_s`` for a full fade);
   panic glides every intensity to 0 over the mute fade, drops scheduled commands, stops
   voices and hands every channel back to direct knob control.
6. **Layers**: one control layer at a time drives a channel's knobs (direct knobs, follow, spatial
   sources, clips: :data:`~vibsynth.engine.commands.LAYER_NAMES`); :class:`SetLayer` changes
   it in stream order and a knob move reaches only the channels its layer drives when it
   applies. :class:`CancelLayer` drops a layer's moves still waiting in the scheduler.
7. **Voices**: :meth:`play_buffer` adds a recording, played once, to channels (ramped gain,
   5 ms edge fades, then the limiter's final clip); the lab plays its stimuli this way.
8. **Output tap**: :meth:`read_output` returns the newest rendered frames (meters, spectra).
9. **Trims**: :meth:`set_trim` gives channels a calibration trim (a channel whose actuator
   differs from the one the bank was equalised for, :mod:`vibsynth.dsp.channel_trim`): a
   balance offset added to the balance knob and a gain read from a curve over the bank's
   levels at the channel's effective position, both applied after the layers resolved the
   knobs (direct knobs, follow, sources and clips all get them) and before the limiter; a new
   trim glides in over ``glide_s`` (50 ms by default). Voices are not trimmed.

Commands
--------
:meth:`submit` pushes a command into a fixed-size single-producer ring in the compiled
core (:mod:`vibsynth.engine._core`); producers serialise on a lock the audio thread never
takes. At the start of each block the audio thread takes at most ``DRAIN_MAX`` (1024)
commands from the ring (after the scheduled commands due at that very sample, which were
submitted before them): immediate commands apply at the block's first sample; commands
with a later ``at_frame`` go into a binary heap keyed (frame, sequence), preallocated to
``schedule_capacity``, and apply at **exactly** that sample (the block is split there); a
command whose frame has already passed applies at the block's first sample and is counted
in ``stats.late_commands``. The cap is enforced on the control side: :meth:`submit`
raises :class:`~vibsynth.errors.ScheduleFullError` when ``schedule_capacity`` commands
are waiting, so per-block work stays O(DRAIN_MAX log capacity) whatever arrives.
``applied_seq`` is the highest sequence number the audio thread has taken (applied, or
placed on its timeline if scheduled).

Real-time safety
----------------
The whole per-block path (hand-off, scheduler, knobs, crossfade, limiter and the
PortAudio callback itself, see :meth:`callback_addresses`) is C that never touches
Python objects: the audio thread does not need the GIL, allocates nothing, takes no
lock and never logs. Requests larger than ``max_block`` are rendered in pieces (so
commands are taken at the same points whatever the caller's block size).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from vibsynth.engine import _core
from vibsynth.engine.bank import NoiseBank
from vibsynth.engine.commands import LAYER_NAMES, CancelLayer, Command, Panic, SetGlide, SetKnob, SetLayer, SetMute
from vibsynth.errors import EngineBusyError, ParameterError, ScheduleFullError
from vibsynth.limits import (
    ACTUATOR_BOOST_MAX_DB,
    BANK_LEVELS_MAX,
    ENGINE_RAMP_MAX_S,
    MAX_CHANNELS,
    SCHEDULE_CAPACITY_MAX,
    VOICE_GAIN_MAX,
    VOICE_GLIDE_MAX_S,
)

if TYPE_CHECKING:
    from vibsynth.settings.models_config import Audio, Knobs

__all__ = [
    "Engine",
    "EngineStats",
    "KNOB_FADE_IN",
    "DEFAULT_SCHEDULE_CAPACITY",
    "TAP_MAX_FRAMES",
    "MAX_VOICE_SECONDS",
    "TRIM_GLIDE_S",
    "TRIM_GAIN_MAX_DB",
]

#: Intensity knobs below this also fade linearly to silence (no step at 0).
KNOB_FADE_IN = 0.01

#: Timetagged commands that may wait at once (``engine.schedule_capacity`` in the config).
DEFAULT_SCHEDULE_CAPACITY = 10_000

#: Slots of the command hand-off ring (a power of two).
RING_CAPACITY = 16_384

_ALL_CHANNELS = (1 << 64) - 1

#: Most frames :meth:`Engine.read_output` returns at once.
TAP_MAX_FRAMES = _core.TAP_FRAMES // 2

#: Longest recording :meth:`Engine.play_buffer` accepts (seconds).
MAX_VOICE_SECONDS = 600.0

#: Voice buffers kept alive at most (each until the audio thread no longer reads it).
_MAX_VOICE_BUFFERS = 256

#: Default glide of a new trim (s).
TRIM_GLIDE_S = 0.05
#: Largest trim gain (dB): the actuator boost limit's ceiling.
TRIM_GAIN_MAX_DB = ACTUATOR_BOOST_MAX_DB
#: Distinct trim curves an engine keeps alive (the audio thread may read any it was sent).
_MAX_TRIM_CURVES = 4096


class EngineStats:
    """Counters of the engine and its output, read from any thread.

    Attributes
    ----------
    blocks : int
        Render calls.
    callbacks : int
        Blocks delivered by the compiled PortAudio callback.
    underflows : int
        Output underflows (counted by the compiled PortAudio callback, or by another output).
    late_commands : int
        Scheduled commands whose frame had already passed when they arrived.
    schedule_full : int
        Timetagged commands refused because ``schedule_capacity`` were waiting.
    pending : int
        Timetagged commands waiting for their frame.
    load_last, load_peak, load_avg : float
        Render time as a fraction of the block period (last, peak since
        :meth:`take_peak`, exponential average).
    output_errors : int
        Device errors the output recovered from.
    """

    def __init__(self, core: _core.Core) -> None:
        self._core = core
        self.output_errors = 0

    blocks = property(lambda self: self._core.blocks)
    callbacks = property(lambda self: self._core.callbacks)
    late_commands = property(lambda self: self._core.late_commands)
    schedule_full = property(lambda self: self._core.schedule_full)
    pending = property(lambda self: self._core.pending)
    load_last = property(lambda self: self._core.load_last)
    load_peak = property(lambda self: self._core.load_peak)
    load_avg = property(lambda self: self._core.load_avg)

    @property
    def underflows(self) -> int:
        return self._core.underflows

    def count_underflow(self) -> None:
        """Count one underflow seen by an output other than the compiled callback (e.g. the null clock)."""
        self._core.add_underflows(1)

    def take_peak(self) -> float:
        """Peak load since the last call (and reset it)."""
        return self._core.take_peak()


class Engine:
    """Multi-channel texture renderer over a :class:`~vibsynth.engine.bank.NoiseBank`.

    Parameters
    ----------
    bank : NoiseBank
    channels : int
        Output channels (each with its own knobs and read offset).
    ceiling_db, range_db : float
        Intensity mapping: knob 1 -> ``ceiling_db`` band level, (0, 1] spans ``range_db``.
    glide_s : float
        Initial glide of every channel (0 = jump).
    mute_fade_s : float
        Duration of a full mute/unmute/panic fade.
    limiter_ceiling : float
        No output sample exceeds this in absolute value (0 < ceiling <= 1).
    initial_intensity, initial_balance : float
    max_block : int
        Largest block rendered in one piece.
    schedule_capacity : int
        Most timetagged commands that may wait at once; more are refused.

    Attributes
    ----------
    fs : float
    channels : int
    stats : EngineStats
    """

    def __init__(
        self,
        bank: NoiseBank,
        *,
        channels: int = 1,
        ceiling_db: float = -40.0,
        range_db: float = 40.0,
        glide_s: float = 0.02,
        mute_fade_s: float = 0.01,
        limiter_ceiling: float = 0.891,
        initial_intensity: float = 0.0,
        initial_balance: float = 0.0,
        max_block: int = 4096,
        schedule_capacity: int = DEFAULT_SCHEDULE_CAPACITY,
    ) -> None:
        if int(channels) != channels or channels < 1 or channels > MAX_CHANNELS:
            raise ParameterError(f"channels must be an integer in 1..{MAX_CHANNELS}, got {channels!r}")
        for name, value in (
            ("ceiling_db", ceiling_db),
            ("range_db", range_db),
            ("glide_s", glide_s),
            ("mute_fade_s", mute_fade_s),
            ("limiter_ceiling", limiter_ceiling),
        ):
            if not math.isfinite(value):
                raise ParameterError(f"{name} must be finite, got {value!r}")
        if range_db <= 0:
            raise ParameterError(f"range_db must be > 0, got {range_db}")
        if not (0 <= glide_s <= ENGINE_RAMP_MAX_S and 0 <= mute_fade_s <= ENGINE_RAMP_MAX_S):
            raise ParameterError(
                f"glide_s and mute_fade_s must be in [0, {ENGINE_RAMP_MAX_S:g}] s, got {glide_s!r} and {mute_fade_s!r}"
            )
        if not 0 < limiter_ceiling <= 1:
            raise ParameterError(f"limiter_ceiling must be in (0, 1], got {limiter_ceiling}")
        if not 0.0 <= initial_intensity <= 1.0:
            raise ParameterError(f"initial intensity must be in [0, 1], got {initial_intensity}")
        if max_block < 1 or max_block >= bank.n_samples:
            raise ParameterError(f"max_block must be in 1..{bank.n_samples - 1}, got {max_block}")
        if int(schedule_capacity) != schedule_capacity or not 1 <= schedule_capacity <= SCHEDULE_CAPACITY_MAX:
            raise ParameterError(
                f"schedule_capacity must be an integer in 1..{SCHEDULE_CAPACITY_MAX}, got {schedule_capacity!r}"
            )
        if bank.levels > BANK_LEVELS_MAX:
            raise ParameterError(f"the engine supports up to {BANK_LEVELS_MAX} bank levels, got {bank.levels}")
        self.bank = bank
        self.fs = float(bank.fs)
        self.channels = int(channels)
        self.ceiling_db = float(ceiling_db)
        self.range_db = float(range_db)
        self.limiter_ceiling = float(limiter_ceiling)
        self.mute_fade_s = float(mute_fade_s)
        self.max_block = int(max_block)
        self.schedule_capacity = int(schedule_capacity)
        self._signals = np.ascontiguousarray(bank.signals, dtype=np.float32)
        self._peaks = np.ascontiguousarray(bank.peaks, dtype=np.float64)
        self._core = _core.Core(
            self._signals,
            self._peaks,
            float(bank.balances[0]),
            float(bank.balances[-1]),
            [int(o) for o in bank.channel_offsets(self.channels)],
            self.fs,
            self.ceiling_db,
            self.range_db,
            float(glide_s),
            self.mute_fade_s,
            self.limiter_ceiling,
            float(initial_intensity),
            float(initial_balance),
            self.max_block,
            RING_CAPACITY,
            self.schedule_capacity,
        )
        self.stats = EngineStats(self._core)
        # seq of a CMD_VOICE -> (samples, frame before which the audio thread may not have taken it)
        self._voices: dict[int, tuple[NDArray[np.float32], int]] = {}
        # trim curves sent to the audio thread, by content (kept for the engine's lifetime)
        self._trim_curves: dict[bytes, NDArray[np.float32]] = {}
        #: What the bank was built for (a :class:`~vibsynth.engine.trims.TrimContext`), set by whoever built it.
        self.trim_context: object | None = None

    @classmethod
    def from_settings(cls, bank: NoiseBank, knobs: Knobs, audio: Audio) -> Engine:
        """An engine with the ``knobs:`` section's mapping, smoothing, limiter and initial state.

        Parameters
        ----------
        bank : NoiseBank
        knobs : Knobs
            The typed ``knobs:`` section.
        audio : Audio
            The typed ``audio:`` section: ``channels`` outputs, blocks of up to ``block_size``
            frames (1024 when the bank's loop is shorter than a block).
        """
        block = audio.block_size
        return cls(
            bank,
            channels=audio.channels,
            ceiling_db=knobs.ceiling_db,
            range_db=knobs.range_db,
            glide_s=knobs.glide_ms / 1000.0,
            mute_fade_s=knobs.mute_fade_ms / 1000.0,
            limiter_ceiling=knobs.limiter_ceiling,
            initial_intensity=knobs.initial_intensity,
            initial_balance=knobs.initial_balance,
            schedule_capacity=knobs.schedule_capacity,
            max_block=block if 0 < block < bank.n_samples else 1024,
        )

    # ------------------------------------------------------------------ control side
    def submit(self, command: Command) -> int:
        """Hand a command to the audio thread (any thread; never blocks). Returns its sequence number.

        Raises
        ------
        ScheduleFullError
            A timetagged command while ``schedule_capacity`` commands are waiting.
        EngineBusyError
            The hand-off ring is full (the audio thread has stopped taking commands).
        """
        if isinstance(command, SetKnob):
            args = (
                _core.CMD_KNOB,
                0 if command.name == "intensity" else 1,
                float(command.value),
                math.nan if command.glide_s is None else float(command.glide_s),
            )
        elif isinstance(command, SetGlide):
            args = (_core.CMD_GLIDE, 0, float(command.seconds), math.nan)
        elif isinstance(command, SetMute):
            args = (_core.CMD_MUTE, int(bool(command.muted)), 0.0, math.nan)
        elif isinstance(command, Panic):
            args = (_core.CMD_PANIC, 0, 0.0, math.nan)
        elif isinstance(command, SetLayer):
            args = (_core.CMD_LAYER, self._layer_index(command.layer), 0.0, math.nan)
        elif isinstance(command, CancelLayer):
            args = (_core.CMD_CANCEL, self._layer_index(command.layer), 0.0, math.nan)
        else:
            raise ParameterError(f"not an engine command: {command!r}")
        layer = self._layer_index(command.layer) if isinstance(command, SetKnob) else 0
        at = command.at_frame
        return self._push(args, getattr(command, "channels", None), at, layer)

    @staticmethod
    def _layer_index(layer: int) -> int:
        if int(layer) != layer or not 0 <= layer < len(LAYER_NAMES):
            raise ParameterError(f"layer must be 0..{len(LAYER_NAMES) - 1} ({', '.join(LAYER_NAMES)}), got {layer!r}")
        return int(layer)

    def _push(
        self,
        args: tuple[int, int, float, float],
        channels: tuple[int, ...] | None,
        at: int | None,
        layer: int = 0,
        ptr: int = 0,
        length: int = 0,
    ) -> int:
        mask = _ALL_CHANNELS if channels is None else sum(1 << c for c in channels if 0 <= c < self.channels)
        seq = self._core.push(*args, mask, -1 if at is None else max(0, int(at)), layer, ptr, length)
        if seq == -2:
            raise ScheduleFullError(
                f"{self.schedule_capacity} timetagged commands are already waiting (engine.schedule_capacity)"
            )
        if seq < 0:
            raise EngineBusyError("the engine's command queue is full; the audio thread is not taking commands")
        return seq

    @property
    def applied_seq(self) -> int:
        """Highest sequence number the audio thread has taken (applied or scheduled)."""
        return self._core.applied_seq

    @property
    def frame_position(self) -> int:
        """Frames rendered since the engine started (the stream clock of ``at_frame``)."""
        return self._core.frame

    def layers(self) -> list[int]:
        """The control layer driving each channel's knobs, as the audio thread last applied it."""
        return self._core.layers()

    # ------------------------------------------------------------------ voices
    def play_buffer(
        self,
        samples: NDArray[np.floating],
        *,
        channels: tuple[int, ...] | list[int] | None = None,
        gain: float = 1.0,
        at_frame: int | None = None,
    ) -> int:
        """Play a mono recording once on channels, added to the texture (any thread; never blocks).

        The samples are copied (float32) and kept alive until the audio thread is done with
        them. A voice starts on its first sample at ``at_frame`` (exact; None = next block),
        fades in and out over 5 ms at its edges, and replaces the voice a channel was
        playing. The sum with the texture is clipped at the limiter ceiling.

        Parameters
        ----------
        samples : ndarray, shape (n,)
            At the engine's rate, at most :data:`MAX_VOICE_SECONDS` long.
        channels : sequence of int, optional
            0-based; None = every channel.
        gain : float
            Linear gain in [0, 16].
        at_frame : int, optional

        Returns
        -------
        voice : int
            The voice id (its sequence number), as :meth:`voice_ids` reports it.
        """
        data = np.ascontiguousarray(np.asarray(samples, dtype=np.float32))
        if data.ndim != 1 or data.size == 0:
            raise ParameterError(f"a voice needs a non-empty mono recording (shape (n,)), got shape {data.shape}")
        if data.size > MAX_VOICE_SECONDS * self.fs:
            raise ParameterError(f"a voice may last at most {MAX_VOICE_SECONDS:g} s, got {data.size / self.fs:.1f} s")
        if not np.all(np.isfinite(data)):
            raise ParameterError("a voice's samples must be finite (no NaN or infinity)")
        gain = self._voice_gain(gain)
        chans = self._voice_channels(channels)
        self._collect_voices()
        if len(self._voices) >= _MAX_VOICE_BUFFERS:
            raise EngineBusyError(f"{_MAX_VOICE_BUFFERS} voices are still playing or queued")
        seq = self._push((_core.CMD_VOICE, 0, gain, math.nan), chans, at_frame, 0, data.ctypes.data, data.size)
        due = self.frame_position if at_frame is None else max(int(at_frame), self.frame_position)
        self._voices[seq] = (data, due)
        return seq

    def set_buffer_gain(
        self, gain: float, *, channels: tuple[int, ...] | list[int] | None = None, glide_s: float = 0.01
    ) -> None:
        """Glide the gain of the voices channels are playing (does nothing where none plays)."""
        glide = float(glide_s)
        if not (math.isfinite(glide) and 0.0 <= glide <= VOICE_GLIDE_MAX_S):
            raise ParameterError(f"voice gain glide must be in [0, {VOICE_GLIDE_MAX_S:g}] s, got {glide_s!r}")
        self._push((_core.CMD_VOICE, 0, self._voice_gain(gain), glide), self._voice_channels(channels), None)

    def stop_buffer(self, *, channels: tuple[int, ...] | list[int] | None = None) -> None:
        """Fade out (5 ms) the voices channels are playing."""
        self._push((_core.CMD_VOICE_STOP, 0, 0.0, math.nan), self._voice_channels(channels), None)

    def voice_ids(self) -> list[int]:
        """The voice each channel plays (the id :meth:`play_buffer` returned), 0 where none plays."""
        return self._core.voice_ids()

    def buffer_playing(self, channel: int) -> bool:
        """Whether a voice plays on ``channel`` (0-based) now."""
        if int(channel) != channel or not 0 <= channel < self.channels:
            raise ParameterError(f"channel must be in 0..{self.channels - 1}, got {channel!r}")
        return self._core.voice_ids()[int(channel)] != 0

    @staticmethod
    def _voice_gain(gain: float) -> float:
        value = float(gain)
        if not (math.isfinite(value) and 0.0 <= value <= VOICE_GAIN_MAX):
            raise ParameterError(f"voice gain must be in [0, {VOICE_GAIN_MAX:g}], got {gain!r}")
        return value

    def _voice_channels(
        self, channels: tuple[int, ...] | list[int] | None, what: str = "voice"
    ) -> tuple[int, ...] | None:
        if channels is None:
            return None
        chans = tuple(int(c) for c in channels)
        if not chans or any(not 0 <= c < self.channels for c in chans):
            raise ParameterError(f"{what} channels must be in 0..{self.channels - 1}, got {list(channels)!r}")
        return chans

    def _collect_voices(self) -> None:
        """Release the buffers the audio thread will not read again.

        A buffer is done when its command was taken (``applied_seq``), its start frame has
        passed (so it fired, or panic dropped it) and no channel's voice names it.
        """
        if not self._voices:
            return
        frame = self.frame_position  # read before the ids: a voice that fired is visible in them
        applied = self.applied_seq
        playing = set(self._core.voice_ids())
        for seq, (_, due) in list(self._voices.items()):
            if seq <= applied and frame > due and seq not in playing:
                del self._voices[seq]

    # ------------------------------------------------------------------ trims
    def set_trim(
        self,
        gain: float | NDArray[np.floating],
        balance_offset: float = 0.0,
        *,
        channels: tuple[int, ...] | list[int] | None = None,
        glide_s: float = TRIM_GLIDE_S,
        at_frame: int | None = None,
    ) -> int:
        """Give channels a calibration trim (any thread; never blocks). Returns the command's sequence number.

        Parameters
        ----------
        gain : float or ndarray, shape (levels,)
            Linear gain, or one gain per bank level read at the channel's effective bank
            position (its balance plus the offset), interpolated between levels. Each in
            ``(0, 10^(TRIM_GAIN_MAX_DB/20)]``; 1 = no gain.
        balance_offset : float
            Added to the channel's balance knob (knob units), within the bank's balance span.
        channels : sequence of int, optional
            0-based; None = every channel.
        glide_s : float
            The new trim blends in over this long (0 = at once), at most ``VOICE_GLIDE_MAX_S``.
        at_frame : int, optional
        """
        curve = np.asarray(gain, dtype=np.float64)
        if curve.ndim == 0:
            curve = np.full(self.bank.levels, float(curve))
        top = 10.0 ** (TRIM_GAIN_MAX_DB / 20.0)
        if curve.shape != (self.bank.levels,) or not (
            np.all(np.isfinite(curve)) and np.all((curve > 0) & (curve <= top))
        ):
            raise ParameterError(
                f"a trim gain is a number or {self.bank.levels} numbers (one per bank level), each in "
                f"(0, {top:g}] (+{TRIM_GAIN_MAX_DB:g} dB)"
            )
        span = float(self.bank.balances[-1] - self.bank.balances[0])
        offset = float(balance_offset)
        if not (math.isfinite(offset) and abs(offset) <= span):
            raise ParameterError(f"a trim's balance offset must be within +-{span:g}, got {balance_offset!r}")
        glide = float(glide_s)
        if not (math.isfinite(glide) and 0.0 <= glide <= VOICE_GLIDE_MAX_S):
            raise ParameterError(f"trim glide must be in [0, {VOICE_GLIDE_MAX_S:g}] s, got {glide_s!r}")
        chans = self._voice_channels(channels, "trim")
        ptr, length = 0, 0
        if not np.all(curve == 1.0):
            data = np.ascontiguousarray(curve, dtype=np.float32)
            key = data.tobytes()
            if key not in self._trim_curves:
                if len(self._trim_curves) >= _MAX_TRIM_CURVES:
                    raise EngineBusyError(f"{_MAX_TRIM_CURVES} different trims were already sent to this engine")
                self._trim_curves[key] = data
            ptr, length = self._trim_curves[key].ctypes.data, data.size
        return self._push((_core.CMD_TRIM, 0, offset, glide), chans, at_frame, 0, ptr, length)

    def trim_values(self) -> list[tuple[float, float]]:
        """Per channel, (balance offset, trim gain at balance 0 plus the offset) as the audio thread has them."""
        return self._core.trim_values()

    # ------------------------------------------------------------------ output tap
    def read_output(self, frames: int) -> NDArray[np.float32]:
        """The newest ``frames`` frames the engine rendered (zeros before the stream started).

        Parameters
        ----------
        frames : int
            1..:data:`TAP_MAX_FRAMES`.

        Returns
        -------
        out : ndarray, shape (frames, channels), float32
        """
        if int(frames) != frames or not 1 <= frames <= TAP_MAX_FRAMES:
            raise ParameterError(f"frames must be an integer in 1..{TAP_MAX_FRAMES}, got {frames!r}")
        out = np.empty((int(frames), self.channels), dtype=np.float32)
        self._core.read_tap(out)
        return out

    def knob_values(self) -> list[tuple[float, float, bool]]:
        """Current (intensity, balance, muted) per channel, for status display (approximate while gliding)."""
        return self._core.knob_values()

    def set_output_map(self, device_channels: int, columns: list[int]) -> None:
        """Where the PortAudio callback writes each channel: ``columns[c]`` of ``device_channels`` (0-based)."""
        self._core.set_output_map(int(device_channels), [int(c) for c in columns])

    def callback_addresses(self) -> tuple[int, int]:
        """``(PaStreamCallback address, userdata address)`` of the compiled callback.

        The callback renders this engine into an interleaved float32 buffer laid out by
        :meth:`set_output_map` and counts output underflows from PortAudio's status flags.
        It never calls into Python. The engine object must outlive the stream.
        """
        return self._core.addresses()

    def render_into(self, out: NDArray[np.float32]) -> None:
        """Fill ``out`` (shape (frames, channels), float32, C-contiguous, writable) with the next frames.

        Runs in C with the GIL released; allocates nothing.
        """
        self._core.render_into(out)

    def render(self, frames: int) -> NDArray[np.float32]:
        """Render the next ``frames`` frames into a new array.

        Returns
        -------
        out : ndarray, shape (frames, channels), float32
        """
        if int(frames) != frames or frames < 0:
            raise ParameterError(f"frames must be a non-negative integer, got {frames!r}")
        out = np.empty((int(frames), self.channels), dtype=np.float32)
        self.render_into(out)
        return out
