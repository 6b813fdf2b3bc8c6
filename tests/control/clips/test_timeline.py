"""The timeline compiler: clip -> engine knob moves, checked move by move and through a real engine."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from tests.control.clips.helpers import make_clip
from vibsynth.control.clips.timeline import (
    GAIN_MAX,
    LOOPS_MAX,
    RATE_MAX,
    RATE_MIN,
    SMOOTH_TOLERANCE,
    ClipTimeline,
    KnobMove,
    check_play_args,
)
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.formats.basis_file import default_basis

FS = 8000.0


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=FS, loop_seconds=1.0, levels=15, seed=4))


def engine_for(bank, **kw) -> Engine:
    return Engine(bank, channels=1, glide_s=0.0, **kw)


def play_through(engine: Engine, moves, frames: int, rng: np.random.Generator) -> list[tuple[int, float, float]]:
    """Submit every move timetagged, render in random blocks; (frame, intensity, balance) after each block."""
    for m in moves:
        engine.submit(SetKnob(m.knob, m.value, at_frame=m.frame, glide_s=m.glide_s))
    out = []
    pos = 0
    while pos < frames:
        n = int(rng.integers(1, 97))
        engine.render(n)
        pos += n
        k, b, _ = engine.knob_values()[0]
        out.append((pos, k, b))
    return out


def ideal(keys: list[tuple[int, float]], frame: int, before: float) -> float:
    """The knob after ``frame`` frames: piecewise linear through (frame, value) keys, left-open pieces."""
    value = before
    for (f0, v0), (f1, v1) in zip(keys, keys[1:]):
        if f0 < frame <= f1:
            return v0 + (v1 - v0) * (frame - f0) / (f1 - f0) if f1 > f0 else v1
    if keys and frame > keys[-1][0]:
        value = keys[-1][1]
    elif keys and frame > keys[0][0]:
        value = keys[0][1]
    return value


# --------------------------------------------------------------------------- move by move
def test_a_linear_segment_is_exactly_one_engine_glide():
    clip = make_clip([(0, 0.2, -1.0), (500, 0.8, 1.0), (1000, 0.4, 1.0)], duration_ms=1000)
    moves = list(ClipTimeline(clip, fs=1000.0, start_frame=100).moves())
    assert moves == [
        KnobMove(100, "balance", -1.0, 0.0),
        KnobMove(100, "balance", 1.0, 0.5),
        KnobMove(100, "intensity", 0.2, 0.0),
        KnobMove(100, "intensity", 0.8, 0.5),
        KnobMove(600, "intensity", 0.4, 0.5),
    ]


def test_hold_jumps_at_the_next_keyframe():
    clip = make_clip([(0, 0.3, 0.0, "hold"), (200, 0.7, 0.5, "hold"), (400, 0.1, 0.5)], duration_ms=600)
    moves = [m for m in ClipTimeline(clip, fs=1000.0).moves() if m.knob == "intensity"]
    assert moves == [
        KnobMove(0, "intensity", 0.3, 0.0),
        KnobMove(200, "intensity", 0.7, 0.0),
        KnobMove(400, "intensity", 0.1, 0.0),
    ]


def test_smooth_stays_within_the_tolerance_of_the_clip_curve(bank, rng):
    clip = make_clip([(0, 0.0, -2.0, "smooth"), (400, 1.0, 2.0, "smooth"), (700, 0.2, 0.0)], duration_ms=800)
    timeline = ClipTimeline(clip, fs=FS)
    pieces = list(timeline.pieces("intensity"))
    assert 3 <= sum(1 for p in pieces if p.t0 < 400) <= 32  # balance spans 4 knob units here
    for knob, index in (("intensity", 0), ("balance", 1)):
        for piece in timeline.pieces(knob):
            for t in np.linspace(piece.t0, piece.t1, 9):
                assert abs(piece.at(t) - clip.value_at(t)[index]) <= SMOOTH_TOLERANCE + 1e-12
    # and the engine plays those pieces: within the tolerance plus one frame's slope of the curve
    played = play_through(engine_for(bank), timeline.moves(), int(0.8 * FS), rng)
    slope = 1.0 / 400 * 1.5 * 1000 / FS  # smoothstep's steepest slope, per frame
    for frame, k, b in played:
        want_k, want_b = clip.value_at(1000.0 * frame / FS)
        assert abs(k - want_k) <= SMOOTH_TOLERANCE + slope + 1e-9
        assert abs(b - want_b) <= SMOOTH_TOLERANCE + 4 * slope + 1e-9


def test_a_transient_jumps_to_the_max_and_glides_back_to_the_curve():
    clip = make_clip([(0, 0.4, 0.0), (1000, 0.4, 0.0)], transients=[(300, 0.9, 2.0, 100)], duration_ms=1000)
    moves = list(ClipTimeline(clip, fs=1000.0).moves())
    assert KnobMove(300, "intensity", 0.9, 0.0) in moves
    assert KnobMove(300, "intensity", 0.4, 0.1) in moves
    assert KnobMove(300, "balance", 2.0, 0.0) in moves
    assert KnobMove(300, "balance", 0.0, 0.1) in moves
    # a transient quieter than the curve leaves the intensity alone (max), moves only the balance
    soft = make_clip([(0, 0.6, 0.0), (1000, 0.6, 0.0)], transients=[(300, 0.2, 1.0, 50)], duration_ms=1000)
    moves = list(ClipTimeline(soft, fs=1000.0).moves())
    assert [m for m in moves if m.knob == "intensity"] == [KnobMove(0, "intensity", 0.6, 0.0)]
    assert KnobMove(300, "balance", 1.0, 0.0) in moves


def test_transient_decay_lands_on_a_moving_curve_and_a_second_transient_takes_over():
    clip = make_clip(
        [(0, 0.0, 0.0), (1000, 1.0, 0.0)], transients=[(200, 0.9, 0.0, 200), (300, 0.5, 0.0, 100)], duration_ms=1000
    )
    pieces = list(ClipTimeline(clip, fs=1000.0).pieces("intensity"))
    first = next(p for p in pieces if p.t0 == 200)
    # the first decay aims at the curve at 400 ms (0.4) and is cut at 300 ms, half way: 0.65
    assert (first.t1, first.v0, first.v1) == (300, 0.9, pytest.approx(0.65))
    second = next(p for p in pieces if p.t0 == 300)
    assert (second.t1, second.v0, second.v1) == (400, pytest.approx(0.65), pytest.approx(0.4))
    after = next(p for p in pieces if p.t0 == 400)
    assert after.v0 == pytest.approx(0.4) and after.t1 == 1000 and after.v1 == 1.0


def test_rate_stretches_time_and_gain_scales_intensity_with_an_exact_clamp():
    clip = make_clip([(0, 0.0, 0.0), (1000, 1.0, 0.0)], duration_ms=1000)
    fast = ClipTimeline(clip, fs=1000.0, rate=2.0)
    assert [m for m in fast.moves() if m.knob == "intensity"][-1] == KnobMove(0, "intensity", 1.0, 0.5)
    assert fast.end_frame == 500
    loud = list(ClipTimeline(clip, fs=1000.0, gain=2.0).pieces("intensity"))
    assert [(p.t0, p.t1, p.v0, p.v1) for p in loud] == [(0.0, 500.0, 0.0, 1.0), (500.0, 1000.0, 1.0, 1.0)]
    half = [m for m in ClipTimeline(clip, fs=1000.0, gain=0.5).moves() if m.knob == "intensity"]
    assert half[-1] == KnobMove(0, "intensity", 0.5, 1.0)


def test_balance_is_clamped_to_the_live_range():
    clip = make_clip([(0, 0.5, -3.0), (100, 0.5, 3.0)], duration_ms=100)
    pieces = list(ClipTimeline(clip, fs=1000.0, balance_limits=(-1.0, 1.0)).pieces("balance"))
    assert [(p.t0, p.t1, p.v0, p.v1) for p in pieces] == [
        (0.0, pytest.approx(100 / 3), -1.0, -1.0),
        (pytest.approx(100 / 3), pytest.approx(200 / 3), -1.0, 1.0),
        (pytest.approx(200 / 3), 100.0, 1.0, 1.0),
    ]


def test_loops_repeat_the_loop_region_then_play_the_tail():
    clip = make_clip(
        [(0, 0.1, 0.0), (100, 0.5, 0.0), (200, 0.9, 0.0), (300, 0.0, 0.0)], duration_ms=300, loop=(100, 200)
    )
    timeline = ClipTimeline(clip, fs=1000.0, loops=3)
    assert timeline.end_frame == 500  # 0..200, 100..200 twice, 200..300
    intensity = [m for m in timeline.moves() if m.knob == "intensity"]
    assert intensity == [
        KnobMove(0, "intensity", 0.1, 0.0),
        KnobMove(0, "intensity", 0.5, 0.1),
        KnobMove(100, "intensity", 0.9, 0.1),
        KnobMove(200, "intensity", 0.5, 0.0),  # back to the loop start
        KnobMove(200, "intensity", 0.9, 0.1),
        KnobMove(300, "intensity", 0.5, 0.0),
        KnobMove(300, "intensity", 0.9, 0.1),
        KnobMove(400, "intensity", 0.0, 0.1),  # the tail
    ]
    assert timeline.position(150).clip_ms == 150 and timeline.position(150).loops_left == 2
    assert (timeline.position(250).clip_ms, timeline.position(250).loop_pass, timeline.position(250).loops_left) == (
        150,
        1,
        1,
    )
    assert timeline.position(450).loop_pass == -1 and timeline.position(450).clip_ms == 250
    assert timeline.position(500).ended and not timeline.position(499).ended


def test_endless_loops_without_loop_points_repeat_the_whole_clip_lazily():
    clip = make_clip([(0, 0.0, 0.0), (50, 1.0, 0.0), (100, 0.0, 0.0)], duration_ms=100)
    timeline = ClipTimeline(clip, fs=1000.0, loops=0)
    assert timeline.end_frame is None
    moves = list(itertools.islice((m for m in timeline.moves() if m.knob == "intensity"), 2000))
    assert moves[-1].frame > 60_000  # ten thousand passes and counting
    assert timeline.position(123_456).loops_left == -1
    assert timeline.position(123_425).clip_ms == pytest.approx(25)


def test_long_lines_are_cut_to_the_longest_glide():
    clip = make_clip([(0, 0.0, 0.0), (25_000, 1.0, 0.0)], duration_ms=25_000)
    moves = [m for m in ClipTimeline(clip, fs=1000.0, glide_max_s=10.0).moves() if m.knob == "intensity"]
    assert moves == [
        KnobMove(0, "intensity", 0.0, 0.0),
        KnobMove(0, "intensity", 0.4, 10.0),
        KnobMove(10_000, "intensity", 0.8, 10.0),
        KnobMove(20_000, "intensity", 1.0, 5.0),
    ]


@pytest.mark.parametrize(
    ("gain", "rate", "loops", "message"),
    [
        (math.nan, 1.0, 1, "gain must be a finite number"),
        (-0.5, 1.0, 1, f"gain -0.5 is outside the allowed range [0, {GAIN_MAX:g}]"),
        (1.0, -1.0, 1, f"rate -1 is outside the allowed range [{RATE_MIN:g}, {RATE_MAX:g}]"),
        (1.0, math.inf, 1, "rate must be a finite number"),
        (1.0, 1.0, 10**9, f"loops 1e+09 is outside the allowed range [0, {LOOPS_MAX}]"),
        (1.0, 1.0, 2.5, "loops must be a whole number"),
    ],
)
def test_bad_play_arguments_name_the_range(gain, rate, loops, message):
    with pytest.raises(ParameterError, match=message.replace("[", r"\[").replace("]", r"\]").replace("+", r"\+")):
        check_play_args(gain, rate, loops)


# --------------------------------------------------------------------------- through a real engine
@pytest.mark.parametrize("seed", range(6))
def test_random_linear_clips_play_sample_exactly_through_the_engine(bank, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 9))
    times = np.sort(rng.choice(np.arange(0, 1500), size=n, replace=False)).astype(float)
    times[0] = 0.0
    keys = [(t, float(rng.uniform(0, 1)), float(rng.uniform(-3, 3))) for t in times]
    duration = float(times[-1] + rng.integers(1, 200))
    clip = make_clip(keys, duration_ms=duration)
    gain, rate = float(rng.uniform(0.2, 1.0)), float(rng.uniform(0.5, 2.0))
    start = int(rng.integers(0, 400))
    timeline = ClipTimeline(clip, fs=FS, start_frame=start, gain=gain, rate=rate)
    frames = [start + int(round(t * FS / (1000.0 * rate))) for t in times]
    ideal_i = [(f, k[1] * gain) for f, k in zip(frames, keys)]
    ideal_b = [(f, k[2]) for f, k in zip(frames, keys)]
    played = play_through(engine_for(bank), timeline.moves(), timeline.end_frame + 300, rng)
    for frame, k, b in played:
        assert k == pytest.approx(ideal(ideal_i, frame, 0.0), abs=1e-9), frame
        assert b == pytest.approx(ideal(ideal_b, frame, 0.0), abs=1e-9), frame
