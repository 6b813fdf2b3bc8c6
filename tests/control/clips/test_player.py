"""The live clip player on a real Controller and Engine, rendered block by block (ticks driven by the test)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.control.clips.helpers import make_clip
from vibsynth.control.clips.player import MAX_IN_FLIGHT, MAX_QUEUED_PER_CHANNEL, ClipPlayer
from vibsynth.control.clips.timeline import ClipTimeline
from vibsynth.control.controller import Controller
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError, ScheduleFullError
from vibsynth.formats.basis_file import default_basis
from vibsynth.settings.clips import UnknownClipError

FS = 8000.0
BLOCK = 64

RAMP = make_clip([(0, 0.2, -1.0), (200, 0.8, 1.0), (400, 0.1, 0.0)], duration_ms=500, name="ramp")
STEPS = make_clip([(0, 0.6, 2.0, "hold"), (100, 0.3, -2.0, "hold"), (200, 0.9, 0.5)], duration_ms=300, name="steps")
LOOP = make_clip([(0, 0.1, 0.0), (50, 0.7, 1.0), (100, 0.1, 0.0)], duration_ms=100, name="loop")
CLIPS = {c.name: c for c in (RAMP, STEPS, LOOP)}


def resolve(name: str):
    try:
        return CLIPS[name]
    except KeyError:
        raise UnknownClipError(f"unknown clip {name!r}") from None


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=FS, loop_seconds=1.0, levels=15, seed=4))


class Rig:
    """An engine, a controller and a player, rendered block by block with a tick before each block."""

    def __init__(self, bank, channels: int = 2, **engine_kw) -> None:
        self.engine = Engine(bank, channels=channels, glide_s=0.0, max_block=BLOCK, **engine_kw)
        self.controller = Controller(self.engine, initial_glide_s=0.0)
        self.player = ClipPlayer(self.controller, resolve, start_margin_frames=0)
        self.trace: list[tuple[int, list[tuple[float, float, bool]]]] = []

    @property
    def now(self) -> int:
        return self.engine.frame_position

    def run_to(self, frame: int) -> None:
        while self.now < frame:
            self.player.tick()
            self.engine.render(min(BLOCK, frame - self.now))
            self.trace.append((self.now, self.engine.knob_values()))

    def knobs(self, channel: int) -> tuple[float, float]:
        k, b, _ = self.engine.knob_values()[channel]
        return k, b


def ideal(timeline: ClipTimeline, frame: int) -> tuple[float, float]:
    """The knobs a timeline's moves give after ``frame`` frames (piecewise linear, left-open pieces)."""
    out = []
    for knob in ("intensity", "balance"):
        value = None
        for piece in timeline.pieces(knob):  # type: ignore[arg-type]
            f0, f1 = timeline.frame_of(piece.t0), timeline.frame_of(piece.t1)
            if f0 < frame <= f1 and f1 > f0:
                value = piece.v0 + (piece.v1 - piece.v0) * (frame - f0) / (f1 - f0)
            elif frame > f1:
                value = piece.v1
        out.append(value)
    return out[0], out[1]  # type: ignore[return-value]


def test_a_clip_drives_the_knobs_sample_exactly_then_hands_back_to_the_knob_state(bank):
    rig = Rig(bank)
    rig.controller.set_texture(0.3, 0.5, channels=[0])
    rig.run_to(800)
    start = 1000
    timeline = rig.player.play("ramp", channels=[0], at_frame=start)
    assert timeline.start_frame == start and timeline.end_frame == start + 4000
    rig.run_to(start)
    assert rig.knobs(0) == pytest.approx((0.3, 0.5))  # untouched until the exact frame
    assert rig.controller.driver(0) == "clip"
    rig.controller.set_knob("intensity", 0.45, channels=[0])  # remembered under the clip
    rig.run_to(timeline.end_frame)
    for frame, values in rig.trace:
        if start < frame <= timeline.end_frame:
            assert values[0][:2] == pytest.approx(ideal(timeline, frame), abs=1e-9), frame
            assert values[1][:2] == (0.0, 0.0)  # the other channel never moved
    rig.run_to(timeline.end_frame + 400)  # the end is acted on at the next tick: back to the knob state
    assert rig.controller.driver(0) == "knobs"
    assert rig.knobs(0) == pytest.approx((0.45, 0.5))
    assert rig.player.playing(0) is None and rig.player.stats.ended == 1


def test_a_later_play_replaces_the_clip_on_its_channel_and_the_first_goes_on_elsewhere(bank):
    rig = Rig(bank)
    first = rig.player.play("ramp", at_frame=200)  # both channels
    rig.run_to(600)
    second = rig.player.play("steps", channels=[1], at_frame=1500)
    assert rig.player.playing(1).name == "ramp"  # until 1500
    rig.run_to(1600)
    assert rig.player.playing(1).name == "steps" and rig.player.playing(0).name == "ramp"
    rig.run_to(first.end_frame + BLOCK)
    for frame, values in rig.trace:
        if 200 < frame <= first.end_frame:
            assert values[0][:2] == pytest.approx(ideal(first, frame), abs=1e-9), frame
        if 200 < frame <= 1500:
            assert values[1][:2] == pytest.approx(ideal(first, frame), abs=1e-9), frame
        elif 1500 < frame <= second.end_frame:
            assert values[1][:2] == pytest.approx(ideal(second, frame), abs=1e-9), frame
    assert rig.player.stats.replaced >= 1
    assert rig.player.playing(1) is None and rig.player.playing(0) is None  # both ended
    assert rig.controller.driver(1) == "knobs"


def test_plays_timetagged_out_of_order_queue_in_start_order(bank):
    rig = Rig(bank)
    late = rig.player.play("steps", channels=[0], at_frame=3000)
    early = rig.player.play("ramp", channels=[0], at_frame=1000)  # arrives second, starts first
    assert rig.player.playing(0).name == "ramp" and not rig.player.playing(0).started
    rig.run_to(late.end_frame)
    for frame, values in rig.trace:
        if frame <= 1000:
            assert values[0][:2] == (0.0, 0.0)
        elif frame <= 3000:
            assert values[0][:2] == pytest.approx(ideal(early, frame), abs=1e-9), frame
        else:
            assert values[0][:2] == pytest.approx(ideal(late, frame), abs=1e-9), frame


def test_a_clip_ending_before_the_next_starts_hands_back_in_between(bank):
    rig = Rig(bank)
    rig.controller.set_texture(0.25, 0.0, channels=[0])
    first = rig.player.play("steps", channels=[0], at_frame=100)  # ends at 2500
    second = rig.player.play("steps", channels=[0], at_frame=4000)
    rig.run_to(3800)
    assert rig.knobs(0) == pytest.approx((0.25, 0.0))  # the knob state between the two
    rig.run_to(second.end_frame)
    frames = dict(rig.trace)
    assert frames[first.end_frame - first.end_frame % BLOCK][0][:2] == pytest.approx((0.9, 0.5))
    for frame, values in rig.trace:
        if 4000 < frame <= second.end_frame:
            assert values[0][:2] == pytest.approx(ideal(second, frame), abs=1e-9), frame


def test_stop_now_glides_back_over_the_release_and_a_timed_stop_cuts_at_its_frame(bank):
    rig = Rig(bank)
    rig.controller.set_texture(0.5, 0.0, channels=[0, 1])
    timeline = rig.player.play("ramp", at_frame=64)
    rig.run_to(1024)
    playing = rig.knobs(0)
    assert rig.player.stop(channels=[0], release_s=0.05) == 1  # 400 frames
    rig.run_to(1024 + 200)
    k, _ = rig.knobs(0)
    assert k == pytest.approx(playing[0] + (0.5 - playing[0]) * 200 / 400, abs=1e-9)
    rig.run_to(1024 + 400)
    assert rig.knobs(0) == pytest.approx((0.5, 0.0))
    assert rig.player.playing(0) is None and rig.player.playing(1).name == "ramp"
    rig.player.stop(channels=[1], at_frame=2048)
    rig.run_to(2048 + BLOCK)
    for frame, values in rig.trace:
        if 1024 < frame <= 2048:
            assert values[1][:2] == pytest.approx(ideal(timeline, frame), abs=1e-9), frame
    rig.run_to(2048 + 800)
    assert rig.knobs(1) == pytest.approx((0.5, 0.0)) and rig.controller.driver(1) == "knobs"


def test_endless_loops_report_their_position_until_stopped(bank):
    rig = Rig(bank)
    rig.player.play("loop", channels=[0], loops=0, at_frame=0)
    rig.run_to(8000 * 3 + 400)  # 3.05 s: 30 passes and a half
    playing = rig.player.playing(0)
    assert playing.name == "loop" and playing.position.loops_left == -1
    assert playing.position.clip_ms == pytest.approx(50.0, abs=BLOCK * 1000 / FS)
    assert rig.engine.stats.late_commands == 0
    rig.player.stop()
    rig.run_to(rig.now + 800)
    assert rig.player.playing(0) is None and rig.knobs(0)[0] == 0.0


def test_panic_stops_every_clip_and_the_player_plays_again_afterwards(bank):
    rig = Rig(bank)
    rig.player.play("loop", loops=0, at_frame=0)
    rig.run_to(2000)
    rig.controller.panic()
    rig.run_to(4000)
    assert rig.player.playing(0) is None and rig.player.playing(1) is None
    assert rig.knobs(0)[0] == 0.0 and rig.knobs(1)[0] == 0.0
    assert rig.controller.driver(0) == "knobs"
    timeline = rig.player.play("steps", channels=[0], at_frame=5000)
    rig.run_to(5000 + 400)
    assert rig.knobs(0) == pytest.approx(ideal(timeline, rig.now), abs=1e-9)


def test_bad_requests_change_nothing(bank):
    rig = Rig(bank)
    with pytest.raises(UnknownClipError):
        rig.player.play("nope")
    with pytest.raises(ParameterError, match="gain must be a finite number"):
        rig.player.play("ramp", gain=float("nan"))
    with pytest.raises(ParameterError, match=r"rate -1 is outside the allowed range \[0.05, 20\]"):
        rig.player.play("ramp", rate=-1)
    with pytest.raises(ParameterError, match=r"loops 1e\+09 is outside the allowed range \[0, 10000\]"):
        rig.player.play("ramp", loops=10**9)
    with pytest.raises(ParameterError, match="channel 3 does not exist"):
        rig.player.play("ramp", channels=[2])
    assert rig.engine.stats.pending == 0 and rig.player.playing(0) is None and rig.player.stats.plays == 0


def test_plays_waiting_on_a_channel_are_capped(bank):
    rig = Rig(bank)
    for k in range(MAX_QUEUED_PER_CHANNEL):
        rig.player.play("steps", channels=[0], at_frame=10_000 + 100 * k)
    with pytest.raises(ParameterError, match=f"already has {MAX_QUEUED_PER_CHANNEL} clips waiting"):
        rig.player.play("steps", channels=[0], at_frame=50_000)


def test_a_play_flood_on_one_channel_leaves_one_clip_and_a_bounded_schedule(bank):
    rig = Rig(bank)
    rng = np.random.default_rng(7)
    for k in range(2000):
        rig.player.play(str(rng.choice(list(CLIPS))), channels=[int(rng.integers(0, 2))], gain=float(rng.uniform(0, 2)))
        if k % 50 == 0:
            rig.run_to(rig.now + BLOCK)
    assert rig.engine.stats.pending <= rig.player.max_queued  # replaced moves included
    assert len(rig.player._playbacks) <= 4  # per channel: the one playing, and the one it cut until the next tick
    last = rig.player.playing(0)
    rig.run_to(rig.now + 8000)
    assert rig.engine.stats.schedule_full == 0 and last is not None


def test_a_dense_clip_is_fed_a_bounded_amount_at_a_time_and_still_plays_exactly(bank):
    times = np.linspace(0, 1000, 2001)
    dense = make_clip([(t, 0.5 + 0.4 * np.sin(t / 7.0), 0.0) for t in times], duration_ms=1000, name="dense")
    CLIPS["dense"] = dense
    try:
        rig = Rig(bank)
        timeline = rig.player.play("dense", channels=[0], at_frame=0)
        rig.run_to(timeline.end_frame)
        assert max(len(p.in_flight) for p in rig.player._playbacks or [None] if p) <= MAX_IN_FLIGHT
        for frame, values in rig.trace:
            assert values[0][0] == pytest.approx(ideal(timeline, frame)[0], abs=1e-9), frame
    finally:
        del CLIPS["dense"]


def test_a_full_engine_schedule_is_retried_and_counted(bank):
    rig = Rig(bank, schedule_capacity=64)
    for k in range(63):  # someone else's timetagged moves fill the schedule
        rig.controller.set_knob("intensity", 0.5, channels=[1], at_frame=1000 + k)
    timeline = rig.player.play("steps", channels=[0], at_frame=0)  # the takeover fits, its moves do not
    assert rig.player.stats.schedule_full >= 1 and rig.controller.error_counts["clip.schedule_full"] >= 1
    rig.run_to(timeline.end_frame)
    assert rig.engine.stats.late_commands >= 1  # fed once the schedule emptied, late
    for frame, values in rig.trace:
        if frame > 1600:
            assert values[0][:2] == pytest.approx(ideal(timeline, frame), abs=1e-9), frame
    for k in range(64 - rig.engine.stats.pending):
        rig.controller.set_knob("intensity", 0.5, channels=[1], at_frame=10_000 + k)
    with pytest.raises(ScheduleFullError):  # a play whose takeover does not fit is refused whole
        rig.player.play("steps", channels=[1], at_frame=20_000)
    assert rig.player.playing(1) is None


def test_the_control_thread_keeps_a_clip_fed_in_real_time(bank):
    engine = Engine(bank, channels=1, glide_s=0.0, max_block=BLOCK)
    controller = Controller(engine, initial_glide_s=0.0)
    player = ClipPlayer(controller, resolve)
    player.start()
    try:
        timeline = player.play("loop", loops=5)  # 0.5 s
        t0 = time.monotonic()
        while engine.frame_position < timeline.end_frame + 800:  # rendered at the real-time pace
            engine.render(BLOCK)
            time.sleep(max(0.0, t0 + engine.frame_position / FS - time.monotonic()))
        assert engine.stats.late_commands == 0
        assert controller.driver(0) == "knobs" and player.playing(0) is None and player.stats.moves >= 10
    finally:
        player.close()
