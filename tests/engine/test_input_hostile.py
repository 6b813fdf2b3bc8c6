"""The compiled input ring (``vibsynth/engine/_input.c``) called the wrong way from Python: every
call raises TypeError, ValueError or RuntimeError naming what was wrong, and changes nothing.

Issue 31, finding 5: ``run_callback``'s delay converted to integers unchecked (NaN, inf, huge),
and a copy from a NULL buffer in a ring that was never initialised. ``scripts/sanitize.sh`` runs
this file against ASan/UBSan builds. The delays that slept for ages run in a child process.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from tests.isolated import run_python
from vibsynth.engine._input import InputRing

UNINITIALISED_CALLS: dict[str, Callable[[Any], object]] = {
    "read_into of no channels": lambda r: r.read_into(np.zeros((4, 0), np.float32)),
    "read_into": lambda r: r.read_into(np.zeros((4, 2), np.float32)),
    "write of no channels": lambda r: r.write(np.zeros((4, 0), np.float32)),
    "skip": lambda r: r.skip(-1),
    "set_input_map": lambda r: r.set_input_map(2, []),
    "run_callback": lambda r: r.run_callback(16),
    "run_callback of a block": lambda r: r.run_callback(np.zeros((4, 0), np.float32)),
    "addresses": lambda r: r.addresses(),
    "stamp": lambda r: r.stamp(),
    "take_peaks": lambda r: r.take_peaks(),
    "take_load_peak": lambda r: r.take_load_peak(),
    **{
        name: (lambda r, name=name: getattr(r, name))
        for name in (
            "channels",
            "device_channels",
            "capacity",
            "fs",
            "available",
            "frames_written",
            "frames_read",
            "frames_captured",
            "dropped_frames",
            "overflows",
            "input_overflows",
            "input_underflows",
            "callbacks",
            "load_last",
            "load_peak",
            "load_avg",
        )
    },
}


@pytest.mark.parametrize("call", UNINITIALISED_CALLS.values(), ids=UNINITIALISED_CALLS.keys())
def test_every_method_of_an_uninitialised_ring_raises(call):
    ring = InputRing.__new__(InputRing)
    with pytest.raises(RuntimeError, match="InputRing is not initialised"):
        call(ring)


def test_a_second_init_is_refused_and_the_ring_keeps_its_frames(rng):
    ring = InputRing(2, 8, 1000.0)
    frames = rng.standard_normal((5, 2)).astype(np.float32)
    ring.write(frames)
    for args in ((2, 8, 1000.0), (1, 2, 48000.0), (64, 1 << 20, 1.0), (0, 3, float("nan"))):
        with pytest.raises(RuntimeError, match="InputRing is already initialised"):
            ring.__init__(*args)  # type: ignore[misc]
    assert (ring.channels, ring.capacity, ring.fs, ring.available) == (2, 8, 1000.0, 5)
    out = np.zeros((8, 2), np.float32)
    assert ring.read_into(out) == 5
    assert np.array_equal(out[:5], frames)


def test_a_failed_first_init_leaves_it_uninitialised_and_a_good_one_then_works():
    ring = InputRing.__new__(InputRing)
    with pytest.raises(ValueError, match="capacity"):
        ring.__init__(1, 3, 1000.0)  # type: ignore[misc]
    with pytest.raises(RuntimeError, match="not initialised"):
        ring.skip(1)
    ring.__init__(1, 4, 1000.0)  # type: ignore[misc]
    assert ring.write(np.ones((3, 1), np.float32)) == 3
    assert ring.skip(-1) == 3


@pytest.mark.parametrize("frames", [-1, (1 << 26) + 1, 1 << 62])
def test_run_callback_frames_out_of_range_raise(frames):
    ring = InputRing(1, 4, 1000.0)
    with pytest.raises(ValueError, match="block: frames must be in 0..67108864"):
        ring.run_callback(frames)
    assert ring.callbacks == 0


def test_run_callback_frames_beyond_an_integer_raise_overflow():
    ring = InputRing(1, 4, 1000.0)
    with pytest.raises(OverflowError):
        ring.run_callback(1 << 70)


def test_bad_delays_raise_instead_of_sleeping_for_ages():
    out = run_python(
        """
        from vibsynth.engine._input import InputRing
        ring = InputRing(1, 4, 1000.0)
        for delay in (float("nan"), float("inf"), -float("inf"), -1.0, 1e300, 60.5, 9.3e18):
            try:
                ring.run_callback(2, 0, 0.0, 0.0, 0.0, delay)
            except ValueError as exc:
                print(exc)
        ring.run_callback(2, 0, 0.0, 0.0, 0.0, 0.001)  # in range: sleeps 1 ms, then runs
        print(ring.callbacks, ring.frames_written)
        """,
        timeout=60.0,
    )
    lines = out.splitlines()
    assert lines[:-1] == [
        f"delay must be in 0..60 s, got {shown}" for shown in ("nan", "inf", "-inf", "-1", "1e+300", "60.5", "9.3e+18")
    ]
    assert lines[-1] == "1 2"
