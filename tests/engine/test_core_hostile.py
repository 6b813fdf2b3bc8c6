"""The compiled core (``vibsynth/engine/_core.c``) called the wrong way from Python: every call
raises TypeError, ValueError or RuntimeError naming what was wrong, and changes nothing.

Issue 31, findings 1, 2 and 5 (the float-to-integer conversions): each call that crashed, hung or
was undefined behaviour under the sanitizer build is made here. ``scripts/sanitize.sh`` runs this
file against ASan/UBSan builds of the extensions, so a regression fails there even where it does
not crash here. The calls that hung without the GIL run in a child process with a deadline.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from tests.isolated import run_python
from vibsynth.engine import _core

LEVELS, N, CHANNELS, FS = 3, 256, 2, 1000.0
BOTH = (1 << CHANNELS) - 1


def core_args(**changes: Any) -> dict[str, Any]:
    """Valid ``Core`` keyword arguments (a seeded 3-level bank of 256 samples, 2 channels), changed."""
    rng = np.random.default_rng(31)
    signals = rng.uniform(-0.5, 0.5, (LEVELS, N)).astype(np.float32)
    args: dict[str, Any] = dict(
        signals=signals,
        peaks=np.abs(signals).max(axis=1).astype(np.float64),
        balances_lo=-1.0,
        balances_hi=1.0,
        offsets=[0, 17],
        fs=FS,
        ceiling_db=0.0,
        range_db=40.0,
        glide_s=0.01,
        mute_fade_s=0.02,
        limiter_ceiling=0.9,
        initial_intensity=0.5,
        initial_balance=0.0,
        max_block=64,
        ring_capacity=16,
        schedule_capacity=8,
    )
    args.update(changes)
    if "signals" in changes and "peaks" not in changes:
        args["peaks"] = np.abs(args["signals"]).max(axis=1).astype(np.float64)
    return args


def render(core: _core.Core, frames: int) -> np.ndarray:
    out = np.zeros((frames, CHANNELS), np.float32)
    core.render_into(out)
    return out


CURVE = np.linspace(0.5, 1.0, LEVELS, dtype=np.float32)  # a trim curve over the 3 levels (kept alive)


def busy_core() -> _core.Core:
    """A core with a trim, a glide under way and 6 scheduled commands waiting (its heap in use)."""
    core = _core.Core(**core_args())
    core.push(_core.CMD_TRIM, 0, 0.3, math.nan, BOTH, -1, 0, CURVE.ctypes.data, LEVELS)
    core.push(_core.CMD_KNOB, 0, 1.0, 0.2, BOTH, -1)
    for k in range(6):
        core.push(_core.CMD_KNOB, 1, -0.9 + 0.3 * k, 0.0, BOTH, 100 + 20 * k)
    render(core, 64)
    return core


# ---------------------------------------------------------------- finding 1: a second __init__
SECOND_INITS = {
    "the same arguments": core_args(),
    "a smaller schedule capacity": core_args(schedule_capacity=1),
    "more levels (a trim curve checked against 3)": core_args(
        signals=np.random.default_rng(5).uniform(-0.5, 0.5, (5, N)).astype(np.float32)
    ),
    "failing validation after the bank": core_args(
        signals=np.zeros((4, 1024), np.float32), peaks=np.ones(4), fs=math.nan
    ),
    "failing on the peaks": core_args(signals=np.zeros((4, 1024), np.float32), peaks=np.ones(2)),
}


@pytest.mark.parametrize("args", SECOND_INITS.values(), ids=SECOND_INITS.keys())
def test_a_second_init_is_refused_and_the_core_renders_on_unchanged(args):
    core, reference = busy_core(), busy_core()
    with pytest.raises(RuntimeError, match="Core is already initialised"):
        core.__init__(**args)  # type: ignore[misc]
    assert core.pending == reference.pending == 6
    assert core.schedule_capacity == 8
    assert core.trim_values() == reference.trim_values()
    out, expected = render(core, 512), render(reference, 512)  # fires the 6 scheduled moves
    assert np.array_equal(out, expected)
    assert np.abs(out).max() > 0.01
    assert core.pending == 0
    assert core.knob_values() == reference.knob_values()


def test_a_failed_first_init_leaves_it_uninitialised_and_a_good_one_then_works():
    core = _core.Core.__new__(_core.Core)
    with pytest.raises(ValueError, match="fs"):
        core.__init__(**core_args(fs=math.inf))  # type: ignore[misc]
    with pytest.raises(ValueError, match="peaks"):
        core.__init__(**core_args(peaks=np.ones(LEVELS + 1)))  # type: ignore[misc]
    with pytest.raises(RuntimeError, match="Core is not initialised"):
        core.push(_core.CMD_KNOB, 0, 1.0, math.nan, BOTH, -1)
    core.__init__(**core_args())  # type: ignore[misc]
    assert np.array_equal(render(core, 300), render(_core.Core(**core_args()), 300))


# ---------------------------------------------------------------- finding 2: no __init__ at all
def _out() -> np.ndarray:
    return np.zeros((64, CHANNELS), np.float32)


UNINITIALISED_CALLS: dict[str, Callable[[Any], object]] = {
    "push": lambda c: c.push(_core.CMD_KNOB, 0, 0.5, math.nan, BOTH, -1),
    "push scheduled": lambda c: c.push(_core.CMD_KNOB, 0, 0.5, math.nan, BOTH, 10),
    "read_tap": lambda c: c.read_tap(np.zeros((8, CHANNELS), np.float32)),
    "read_tap empty": lambda c: c.read_tap(np.zeros((0, 0), np.float32)),
    "voice_ids": lambda c: c.voice_ids(),
    "trim_values": lambda c: c.trim_values(),
    "layers": lambda c: c.layers(),
    "set_output_map": lambda c: c.set_output_map(2, [0, 1]),
    "knob_values": lambda c: c.knob_values(),
    "take_peak": lambda c: c.take_peak(),
    "add_underflows": lambda c: c.add_underflows(1),
    "addresses": lambda c: c.addresses(),
    "output_stamp": lambda c: c.output_stamp(),
    **{
        name: (lambda c, name=name: getattr(c, name))
        for name in (
            "frame",
            "applied_seq",
            "blocks",
            "underflows",
            "late_commands",
            "ring_full",
            "schedule_full",
            "callbacks",
            "pending",
            "schedule_capacity",
            "load_last",
            "load_peak",
            "load_avg",
        )
    },
}


@pytest.mark.parametrize("call", UNINITIALISED_CALLS.values(), ids=UNINITIALISED_CALLS.keys())
def test_every_method_of_an_uninitialised_core_raises(call):
    core = _core.Core.__new__(_core.Core)
    with pytest.raises(RuntimeError, match="Core is not initialised"):
        call(core)


def test_rendering_an_uninitialised_core_raises_instead_of_looping_without_the_gil():
    out = run_python(
        """
        import numpy as np
        from vibsynth.engine import _core
        core = _core.Core.__new__(_core.Core)
        for call in (lambda: core.render_into(np.zeros((64, 2), np.float32)),
                     lambda: core.render_into(np.zeros((64, 0), np.float32)),
                     lambda: core.run_callback(np.zeros((64, 0), np.float32), 0)):
            try:
                call()
            except RuntimeError as exc:
                print(exc)
        """,
        timeout=60.0,
    )
    assert out.splitlines() == ["Core is not initialised (its __init__ has not succeeded)"] * 3


# ---------------------------------------------------------------- finding 5: floats that became integers
BAD_PUSHES = {
    "NaN intensity": ((_core.CMD_KNOB, 0, math.nan, math.nan, BOTH, -1), "value must be finite"),
    "infinite balance": ((_core.CMD_KNOB, 1, -math.inf, math.nan, BOTH, -1), "value must be finite"),
    "infinite glide": ((_core.CMD_KNOB, 0, 0.5, math.inf, BOTH, -1), "glide must be in"),
    "huge glide": ((_core.CMD_KNOB, 0, 0.5, 1e300, BOTH, -1), "glide must be in"),
    "negative glide": ((_core.CMD_KNOB, 0, 0.5, -1.0, BOTH, -1), "glide must be in"),
    "glide over an hour": ((_core.CMD_KNOB, 0, 0.5, 3600.5, BOTH, -1), "glide must be in"),
    "huge channel glide": ((_core.CMD_GLIDE, 0, 1e300, math.nan, BOTH, -1), "value \\(glide seconds\\) must be in"),
    "NaN channel glide": ((_core.CMD_GLIDE, 0, math.nan, math.nan, BOTH, -1), "value must be finite"),
    "negative channel glide": ((_core.CMD_GLIDE, 0, -0.5, math.nan, BOTH, -1), "value \\(glide seconds\\)"),
    "huge voice glide": ((_core.CMD_VOICE, 0, 0.5, 1e20, BOTH, -1), "glide must be in"),
    "NaN voice gain": ((_core.CMD_VOICE, 0, math.nan, 0.1, BOTH, -1), "value must be finite"),
    "infinite trim glide": ((_core.CMD_TRIM, 0, 0.0, math.inf, BOTH, -1), "glide must be in"),
    "NaN trim offset": ((_core.CMD_TRIM, 0, math.nan, math.nan, BOTH, -1), "value must be finite"),
    "trim curve of other levels": ((_core.CMD_TRIM, 0, 0.0, math.nan, BOTH, -1, 0, CURVE.ctypes.data, 5), "length"),
    "unknown kind": ((0, 0, 0.0, math.nan, BOTH, -1), "kind must be"),
    "kind after the last": ((_core.CMD_TRIM + 1, 0, 0.0, math.nan, BOTH, -1), "kind must be"),
    "knob 2": ((_core.CMD_KNOB, 2, 0.5, math.nan, BOTH, -1), "arg must be 0 \\(intensity\\) or 1"),
    "layer 4": ((_core.CMD_KNOB, 0, 0.5, math.nan, BOTH, -1, 4), "layer must be in 0..3"),
    "switch to layer -1": ((_core.CMD_LAYER, -1, 0.0, math.nan, BOTH, -1), "arg must be a layer"),
    "cancel layer 4": ((_core.CMD_CANCEL, 4, 0.0, math.nan, BOTH, -1), "arg must be a layer"),
    "frame -2": ((_core.CMD_KNOB, 0, 0.5, math.nan, BOTH, -2), "at must be -1"),
    "negative length": ((_core.CMD_VOICE, 0, 0.5, math.nan, BOTH, -1, 0, 0, -1), "length must be >= 0"),
}


@pytest.mark.parametrize(("args", "message"), BAD_PUSHES.values(), ids=BAD_PUSHES.keys())
def test_a_bad_push_raises_naming_the_argument_and_queues_nothing(args, message):
    core = _core.Core(**core_args())
    with pytest.raises(ValueError, match=message):
        core.push(*args)
    render(core, 64)
    assert core.applied_seq == 0  # nothing reached the audio thread
    assert core.push(_core.CMD_KNOB, 0, 0.25, math.nan, BOTH, -1) == 1  # the first sequence number


BAD_INITS = {
    "NaN fs": ({"fs": math.nan}, "fs must be in"),
    "infinite fs": ({"fs": math.inf}, "fs must be in"),
    "zero fs": ({"fs": 0.0}, "fs must be > 0"),
    "negative fs": ({"fs": -48000.0}, "fs must be in"),
    "huge fs": ({"fs": 1e300}, "fs must be in"),
    "NaN glide": ({"glide_s": math.nan}, "glide_s must be in"),
    "huge glide": ({"glide_s": 1e300}, "glide_s must be in"),
    "negative glide": ({"glide_s": -0.1}, "glide_s must be in"),
    "infinite mute fade": ({"mute_fade_s": math.inf}, "mute_fade_s must be in"),
    "huge mute fade": ({"mute_fade_s": 1e18}, "mute_fade_s must be in"),
    "NaN limiter": ({"limiter_ceiling": math.nan}, "limiter_ceiling must be finite"),
    "negative limiter": ({"limiter_ceiling": -1.0}, "limiter_ceiling must be in"),
    "NaN ceiling": ({"ceiling_db": math.nan}, "ceiling_db must be finite"),
    "infinite range": ({"range_db": math.inf}, "range_db must be finite"),
    "NaN intensity": ({"initial_intensity": math.nan}, "initial_intensity must be finite"),
    "infinite balance": ({"initial_balance": -math.inf}, "initial_balance must be finite"),
    "NaN balance range": ({"balances_lo": math.nan}, "balances_lo must be finite"),
    "empty balance range": ({"balances_lo": 1.0, "balances_hi": 1.0}, "balances_lo must be < balances_hi"),
    "float64 signals": ({"signals": np.zeros((LEVELS, N))}, "signals must be"),
    "one level": ({"signals": np.zeros((1, N), np.float32)}, "levels must be in 2..4096"),
    "peaks of other levels": ({"peaks": np.ones(LEVELS - 1)}, "peaks must be"),
    "no channels": ({"offsets": []}, "offsets: channels must be in 1..64"),
    "65 channels": ({"offsets": [0] * 65}, "offsets: channels must be in 1..64"),
    "block of 0": ({"max_block": 0}, "max_block"),
    "block of a whole level": ({"max_block": N}, "max_block"),
    "ring not a power of two": ({"ring_capacity": 12}, "ring_capacity must be a power of two"),
    "huge ring": ({"ring_capacity": 1 << 40}, "ring_capacity"),
    "no schedule": ({"schedule_capacity": 0}, "schedule_capacity must be in"),
}


@pytest.mark.parametrize(("changes", "message"), BAD_INITS.values(), ids=BAD_INITS.keys())
def test_bad_settings_raise_naming_the_argument(changes, message):
    with pytest.raises(ValueError, match=message):
        _core.Core(**core_args(**changes))


def test_offsets_that_are_not_integers_raise_type_error():
    with pytest.raises(TypeError):
        _core.Core(**core_args(offsets=[0.5, 1.5]))
    with pytest.raises(TypeError):
        _core.Core(**core_args(offsets=3))


def test_the_longest_glides_and_fades_render_exactly():
    """An hour's glide (3.6 M samples) and an hour's mute fade are in range: exact linear ramps."""
    core = _core.Core(**core_args(mute_fade_s=3600.0))
    core.push(_core.CMD_KNOB, 0, 1.0, 3600.0, BOTH, -1)
    core.push(_core.CMD_GLIDE, 0, 3600.0, math.nan, 0b10, -1)
    render(core, 100)
    core.push(_core.CMD_KNOB, 1, 1.0, math.nan, 0b10, -1)  # channel 1's glide: an hour
    core.push(_core.CMD_MUTE, 1, 0.0, math.nan, 0b01, -1)
    render(core, 200)
    (k0, b0, muted0), (k1, b1, muted1) = core.knob_values()
    assert k0 == k1 == pytest.approx(0.5 + 0.5 * 300 / 3.6e6, rel=1e-12)
    assert b0 == 0.0 and b1 == pytest.approx(200 / 3.6e6, rel=1e-9)
    assert (muted0, muted1) == (True, False)
    assert np.abs(render(core, 64)[:, 1]).max() > 0.0


def test_a_bad_output_map_raises_and_keeps_the_old_one():
    core = _core.Core(**core_args())
    core.set_output_map(3, [2, 0])
    with pytest.raises(TypeError):
        core.set_output_map(3, 5)
    with pytest.raises(ValueError, match="device column out of range"):
        core.set_output_map(3, [0, 3])
    with pytest.raises(ValueError, match="one device column per engine channel"):
        core.set_output_map(3, [0])
    out = np.zeros((64, 3), np.float32)
    core.run_callback(out, 0)
    assert np.array_equal(out[:, 1], np.zeros(64, np.float32))  # column 1 stays silent: the map is [2, 0]
    assert np.abs(out[:, 0]).max() > 0.0 and np.abs(out[:, 2]).max() > 0.0
