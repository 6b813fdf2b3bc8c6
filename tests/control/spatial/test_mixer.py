"""The sources' mixer: what it drives, when, and how much work a flood costs."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.control.osc.fakes import make_controller
from tests.control.spatial.rig import LINE, SOURCES_LAYER, Clock, knob_moves, make_mixer, spectra
from vibsynth.control import spatial
from vibsynth.control.controller import Controller
from vibsynth.dsp.intensity import knob_to_level_db, level_db_to_knob
from vibsynth.dsp.spatial import mix_sources
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.errors import ScheduleFullError
from vibsynth.settings.models_config import ChannelPosition


@pytest.fixture
def ctl():
    return make_controller(channels=4)


@pytest.fixture
def clock():
    return Clock()


@pytest.fixture
def mixer(ctl, basis, clock):
    return make_mixer(ctl, basis, clock=clock)


def place(mixer, index, position, *, intensity=0.8, balance=0.0, on=True):
    def update(table, t):
        table.set_texture(index, intensity, balance)
        table.set_position(index, position, t)
        table.set_on(index, on, t)

    mixer.apply(update)


def test_a_source_on_an_actuator_plays_exactly_its_own_knobs_there(ctl, mixer, clock, rng):
    for _ in range(5):
        intensity, balance = float(rng.uniform(0.05, 1)), float(rng.uniform(-3.5, 3.5))
        place(mixer, 0, (0.2, 0.0, 0.0), intensity=intensity, balance=balance)
        clock.advance(0.05)
        mixer.step()
        assert mixer.driven()[2] == (round(intensity, 9), round(balance, 9))
        assert ctl.get("texture", 2) == pytest.approx((intensity, balance), abs=1e-9)
        assert ctl.driver(2) == "sources"


def test_weights_lower_the_level_by_10_log10_w(ctl, mixer, clock, rng):
    x = float(rng.uniform(0.1, 0.2))  # between actuators 2 and 3 (0.1 and 0.2 m), radius 0.1 m
    place(mixer, 0, (x, 0.0, 0.0), intensity=0.9, balance=0.5)
    clock.advance(0.05)
    mixer.step()
    driven = mixer.driven()
    assert set(driven) == {1, 2}  # linear law: 0 at the radius, so channels 1 and 4 are not reached
    for channel, d in ((1, x - 0.1), (2, 0.2 - x)):
        w = 1.0 - d / 0.1
        level = knob_to_level_db(driven[channel][0])
        assert level == pytest.approx(knob_to_level_db(0.9) + 10 * math.log10(w), abs=1e-6)
        assert driven[channel][1] == pytest.approx(0.5)
    assert ctl.driver(0) == "knobs" and ctl.driver(3) == "knobs"


def test_two_sources_mix_in_the_perceptual_model(ctl, mixer, clock, basis):
    place(mixer, 0, (0.0, 0.0, 0.0), intensity=0.7, balance=-2.0)
    place(mixer, 1, (0.05, 0.0, 0.0), intensity=0.6, balance=2.0)
    clock.advance(0.05)
    mixer.step()
    w = np.array([[1.0, 0.0, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0]])
    levels = [knob_to_level_db(0.7), knob_to_level_db(0.6)]
    expected = mix_sources(w, levels, [-2.0, 2.0], spectra(basis))
    driven = mixer.driven()
    assert driven[0][0] == pytest.approx(level_db_to_knob(expected.level_db[0]), abs=1e-8)
    assert driven[0][1] == pytest.approx(expected.balance[0], abs=1e-8)
    assert driven[1] == pytest.approx((0.6 + 10 * math.log10(0.5) / 40, 2.0), abs=1e-8)  # only source 2 reaches it


def test_leaving_a_channel_releases_it_to_its_direct_knobs(ctl, mixer, clock):
    ctl.set_texture(0.3, -1.0, channels=[0])
    place(mixer, 0, (0.0, 0.0, 0.0))
    clock.advance(0.05)
    mixer.step()
    assert ctl.get("texture", 0) == pytest.approx((0.8, 0.0))
    ctl.set_knob("intensity", 0.4, channels=[0])  # remembered while the source drives channel 1
    assert ctl.get("texture", 0) == pytest.approx((0.8, 0.0))
    mixer.apply(lambda table, t: table.set_position(0, (0.3, 0.0, 0.0), t))
    clock.advance(0.05)
    mixer.step()
    assert 0 not in mixer.driven() and ctl.driver(0) == "knobs"
    assert ctl.get("texture", 0) == pytest.approx((0.4, -1.0))
    mixer.apply(lambda table, t: table.set_on(0, False, t))
    clock.advance(0.05)
    mixer.step()
    assert mixer.driven() == {} and all(ctl.driver(c) == "knobs" for c in range(4))


def test_a_flood_of_positions_costs_one_mix(ctl, mixer, clock):
    place(mixer, 0, (0.0, 0.0, 0.0))
    clock.advance(0.05)
    mixer.step()
    mixes, commands = mixer.mixes, len(ctl.engine.commands)
    for k in range(10_000):
        mixer.apply(lambda table, t, k=k: table.set_position(0, (0.3 * k / 9999, 0.0, 0.0), t))
    clock.advance(0.05)  # past the glide: the source is at its last target
    mixer.step()
    mixer.step()  # nothing new: no mix
    assert mixer.mixes == mixes + 1
    assert len(ctl.engine.commands) - commands <= 3 * 4  # at most a layer switch and two knobs per channel
    assert set(mixer.driven()) == {2, 3} and mixer.driven()[3][0] == pytest.approx(0.8)


def test_motion_glides_and_the_channels_follow_one_update_ahead(ctl, mixer, clock):
    place(mixer, 0, (0.0, 0.0, 0.0))
    clock.advance(0.05)
    mixer.step()
    clock.advance(0.5)  # at rest for a while: the next change is mixed at once
    mixer.apply(lambda table, t: table.set_position(0, (0.1, 0.0, 0.0), t))  # a 20 ms glide
    mixer.step()
    # mixed where the source will be one update (10 ms) later: half way, gliding over those 10 ms
    intensity = knob_moves(ctl.engine, "intensity")
    assert intensity[0].value == pytest.approx(0.8 + 10 * math.log10(0.5) / 40)
    assert intensity[0].glide_s == pytest.approx(0.01)
    clock.advance(0.005)
    mixer.step()  # too early: at most one mix per update
    assert knob_moves(ctl.engine, "intensity")[0] is intensity[0]
    clock.advance(0.005)
    mixer.step()
    assert 0 not in mixer.driven() and mixer.driven()[1][0] == pytest.approx(0.8)
    clock.advance(0.01)
    mixer.step()
    mixes = mixer.mixes
    clock.advance(0.01)
    mixer.step()
    assert mixer.mixes == mixes  # at rest: no more mixes


def test_speed_drives_the_intensity_through_the_speed_curve(ctl, basis, clock):
    mixer = make_mixer(ctl, basis, clock=clock, speed=True, speed_window_s=0.1, glide_s=0.0)
    place(mixer, 0, (0.0, 0.0, 0.0), intensity=0.2)
    for step in range(1, 21):  # 100 mm/s along x for 200 ms, a position every 10 ms
        clock.advance(0.01)
        mixer.apply(lambda table, t, step=step: table.set_position(0, (0.001 * step, 0.0, 0.0), t))
        mixer.step()
    # the speed curve gives 0.6 at 50 mm/s and 0.85 at 150 mm/s: 0.725 at 100 mm/s; 2 cm from channel 1: w = 0.8
    assert ctl.get("texture", 0)[0] == pytest.approx(0.725 + 10 * math.log10(0.8) / 40, abs=1e-6)
    for _ in range(20):  # positions stop: at rest within one window
        clock.advance(0.01)
        mixer.step()
    assert ctl.get("texture", 0)[0] == 0.0


def test_timetagged_changes_apply_at_their_frame(ctl, mixer, clock):
    engine = ctl.engine
    place(mixer, 0, (0.0, 0.0, 0.0))
    clock.advance(0.05)
    mixer.step()
    frame = engine.frame + 4800  # 100 ms ahead
    mixer.apply(lambda table, t: table.set_texture(0, 0.5, 1.0), at_frame=frame)
    mixer.step()
    assert mixer.pending == 1 and mixer.driven()[0] == (0.8, 0.0)
    engine.frame += 4800 - 240  # 5 ms before it: within one update
    clock.advance(0.095)
    mixer.step()
    assert mixer.pending == 0 and mixer.driven()[0] == (0.5, 1.0)
    moves = knob_moves(engine, "intensity")
    assert moves[0].at_frame == frame


def test_the_schedule_is_bounded(ctl, mixer):
    for k in range(8):
        mixer.apply(lambda table, t: None, at_frame=ctl.engine.frame + 48000 + k)
    with pytest.raises(ScheduleFullError, match="8 timetagged source messages are already waiting"):
        mixer.apply(lambda table, t: None, at_frame=ctl.engine.frame + 48000)
    assert mixer.pending == 8


def test_many_timetagged_changes_due_together_cost_a_bounded_number_of_mixes(ctl, basis, clock):
    mixer = make_mixer(ctl, basis, clock=clock)
    mixer.schedule_capacity = 1000
    for k in range(1000):
        mixer.apply(lambda table, t, k=k: table.set_texture(0, k / 1000, 0.0), at_frame=ctl.engine.frame + 10 + k % 300)
    place(mixer, 0, (0.0, 0.0, 0.0))
    mixes = mixer.mixes
    mixer.step()
    assert mixer.pending == 0 and mixer.mixes - mixes <= 16
    # the latest-timed one won (frames 10 + k % 300: k = 899 is the last of the latest frame)
    assert mixer.read(lambda table, now: table.view(0, now).intensity) == 0.899


def test_panic_turns_the_sources_off(ctl, mixer, clock):
    place(mixer, 0, (0.0, 0.0, 0.0))
    mixer.apply(lambda table, t: None, at_frame=ctl.engine.frame + 48000)
    clock.advance(0.05)
    mixer.start()
    try:
        ctl.panic()
        assert mixer.pending == 0 and mixer.driven() == {}
        assert not mixer.read(lambda table, now: table.view(0, now).on)
        assert ctl.driver(0) == "knobs"
    finally:
        mixer.stop()


def test_the_thread_mixes_soon_after_a_change_and_stop_releases(ctl, basis):
    mixer = make_mixer(ctl, basis, clock=time.monotonic)
    mixer.start()
    try:
        assert spatial.mixer_of(ctl) is mixer
        started = time.monotonic()
        place(mixer, 0, (0.1, 0.0, 0.0))
        while 1 not in mixer.driven() and time.monotonic() - started < 5.0:
            time.sleep(0.001)
        assert mixer.driven()[1] == (0.8, 0.0)
    finally:
        mixer.stop()
    assert spatial.mixer_of(ctl) is None
    assert all(ctl.driver(c) == "knobs" for c in range(4))


def test_on_a_real_engine_the_channels_play_the_mix(basis):
    """The rendered 80-200 Hz band levels differ by 10 log10 of the weights' ratio."""
    from vibsynth.dsp.intensity import intensity_level_db

    bank = build_bank(basis, BankSpec(fs=8000.0, loop_seconds=1.0, levels=9, seed=3))
    engine = Engine(bank, channels=4, glide_s=0.0, max_block=256)
    ctl = Controller(engine, initial_glide_s=0.0)
    clock = Clock()
    mixer = make_mixer(ctl, basis, clock=clock, radius_m=0.15)
    place(mixer, 0, (0.13, 0.0, 0.0), intensity=0.9, balance=0.0)
    clock.advance(0.05)
    mixer.step()
    engine.render(800)  # let the 10 ms glide end
    out = engine.render(8000)
    levels = [intensity_level_db(out[:, c].astype(np.float64), fs=8000.0) for c in range(4)]
    weights = [max(0.0, 1 - abs(0.13 - LINE[c + 1].x) / 0.15) for c in range(4)]
    assert int(np.argmax(levels)) == 1
    for c in range(3):
        assert levels[c] - levels[1] == pytest.approx(10 * math.log10(weights[c] / weights[1]), abs=0.1)
    assert weights[3] == 0.0 and levels[3] == -math.inf


def test_a_layout_channel_list_may_skip_channels(basis):
    ctl = make_controller(channels=4)
    clock = Clock()
    mixer = make_mixer(ctl, basis, clock=clock, positions={2: ChannelPosition(x=0, y=0), 4: ChannelPosition(x=1, y=0)})
    place(mixer, 0, (1.0, 0.0, 0.0))
    clock.advance(0.05)
    mixer.step()
    assert mixer.driven() == {3: (0.8, 0.0)}
    assert [c for c in ctl.engine.commands if isinstance(c, SetKnob) and c.layer == SOURCES_LAYER][-1].channels == (3,)
