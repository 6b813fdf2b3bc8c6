"""The live follower on a real engine and controller, fed by a fake input (seeded signals, stepped by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.control.follow.fakes import tone
from vibsynth.control.follow.follower import HISTORY_STEP_S
from vibsynth.errors import ConfigError, ParameterError

FS = 16000.0


def knob_of(level_db: float, ceiling_db: float = -40.0, range_db: float = 40.0) -> float:
    """The intensity knob that plays a band level (knobs.ceiling_db / range_db defaults)."""
    return 1.0 + (level_db - ceiling_db) / range_db


def test_a_level_step_in_the_input_is_a_knob_step_on_the_output(make_rig):
    rig = make_rig()
    rig.feed(tone(FS, 0.6, 10 ** (-50 / 20)))
    first = rig.plays(0)[0]
    rig.feed(tone(FS, 0.6, 10 ** (-62 / 20), start=int(0.6 * FS)))
    second = rig.plays(0)[0]
    assert first == pytest.approx(knob_of(-50), abs=0.02)
    assert second == pytest.approx(knob_of(-62), abs=0.02)
    assert rig.controller.driver(0) == "follow" and rig.controller.get("intensity", 1) == pytest.approx(
        second, abs=1e-9
    )


def test_gain_moves_the_output_level_by_as_many_db(make_rig):
    rig = make_rig()
    rig.feed(tone(FS, 0.5, 10 ** (-60 / 20)))
    before = rig.plays(0)[0]
    assert rig.follower.set_gain(6.0) == 6.0
    rig.feed(tone(FS, 0.3, 10 ** (-60 / 20), start=int(0.5 * FS)))
    assert rig.plays(0)[0] - before == pytest.approx(6.0 / 40.0, abs=0.01)


def test_the_gate_closes_the_output_below_its_level(make_rig):
    rig = make_rig()
    rig.feed(tone(FS, 0.4, 10 ** (-60 / 20)))
    assert rig.plays(0)[0] > 0.4 and rig.follower.gate_open()
    rig.follower.set_gate(-50.0)
    rig.feed(tone(FS, 0.2, 10 ** (-60 / 20), start=int(0.4 * FS)))
    assert rig.plays(0)[0] == 0.0 and not rig.follower.gate_open()
    assert rig.follower.gate_db == -50.0


@pytest.mark.parametrize("bad", [99.0, -61.0, float("nan")])
def test_a_gain_outside_the_settings_range_is_refused_and_changes_nothing(make_rig, bad):
    rig = make_rig()
    with pytest.raises(ParameterError, match=r"\[-60, 60\]|finite"):
        rig.follower.set_gain(bad)
    assert rig.follower.gain_db == 0.0


def test_a_focus_that_does_not_exist_is_refused(make_rig):
    rig = make_rig(follow={"mode": "audio"})
    with pytest.raises(ParameterError, match="all, effects, bass, beat"):
        rig.follower.set_focus("loud")
    assert rig.follower.set_focus("effects") == "effects"
    rig.feed(np.zeros(256))
    assert {v.focus for v in rig.follower.routes()} == {"effects"}


def test_stereo_input_drives_two_channels_one_to_one(make_rig):
    rig = make_rig(channels=2, inputs=2)
    x = np.stack([tone(FS, 0.5, 10 ** (-50 / 20)), tone(FS, 0.5, 10 ** (-66 / 20))], axis=1)
    rig.feed(x)
    assert rig.plays(0)[0] == pytest.approx(knob_of(-50), abs=0.02)
    assert rig.plays(1)[0] == pytest.approx(knob_of(-66), abs=0.02)


def test_routes_pick_their_inputs_and_add_their_gain(make_rig):
    rig = make_rig(channels=2, inputs=2, follow={"routes": [{"channel": 2, "inputs": [1], "gain_db": -8}]})
    x = np.stack([tone(FS, 0.5, 10 ** (-50 / 20)), tone(FS, 0.5, 10 ** (-70 / 20))], axis=1)
    rig.feed(x)
    assert rig.follower.channels() == (1,)
    assert rig.plays(1)[0] == pytest.approx(knob_of(-58), abs=0.02)
    assert rig.controller.driver(0) == "knobs" and rig.plays(0)[0] == 0.0


def test_a_route_naming_an_input_the_device_lacks_is_one_clear_error(make_rig):
    with pytest.raises(ConfigError, match=r"follow.routes\[0\].inputs = \[3\]: the input has 2 channels"):
        make_rig(channels=1, inputs=2, follow={"routes": [{"channel": 1, "inputs": [3]}]})


def test_follow_off_on_a_channel_hands_it_back_to_the_remembered_knobs(make_rig):
    rig = make_rig()
    rig.controller.set_knob("intensity", 0.2, source="osc")  # direct knobs, remembered under follow
    rig.feed(tone(FS, 0.4, 10 ** (-50 / 20)))
    rig.controller.set_knob("intensity", 0.3, channels=[1], source="osc")
    assert rig.plays(1)[0] == pytest.approx(knob_of(-50), abs=0.02)
    rig.follower.set_channel(1, False)
    rig.feed(tone(FS, 0.2, 10 ** (-50 / 20), start=int(0.4 * FS)))
    assert rig.controller.driver(1) == "knobs" and rig.plays(1)[0] == pytest.approx(0.3)
    assert rig.controller.driver(0) == "follow" and not rig.follower.is_on(1)
    rig.follower.set_channel(1, True)
    rig.feed(tone(FS, 0.1, 10 ** (-50 / 20), start=int(0.6 * FS)))
    assert rig.controller.driver(1) == "follow" and rig.plays(1)[0] == pytest.approx(knob_of(-50), abs=0.02)


def test_a_channel_without_a_route_cannot_be_turned_on(make_rig):
    rig = make_rig(channels=2, follow={"routes": [{"channel": 1}]})
    with pytest.raises(ParameterError, match="channel 2 has no follow route"):
        rig.follower.set_channel(1, True)


@pytest.mark.parametrize("layer", ["clip", "sources"])
def test_a_clip_or_a_source_beats_follow_and_follow_takes_the_channel_back(make_rig, layer):
    rig = make_rig()
    rig.feed(tone(FS, 0.3, 10 ** (-50 / 20)))
    rig.controller.drive(layer, channels=[0], intensity=0.1, balance=1.0, glide_s=0.0, source=layer)
    rig.feed(tone(FS, 0.3, 10 ** (-50 / 20), start=int(0.3 * FS)))
    assert rig.controller.driver(0) == layer and rig.plays(0) == pytest.approx((0.1, 1.0))
    assert rig.controller.driver(1) == "follow"
    rig.controller.release(layer, channels=[0], glide_s=0.0, source=layer)
    rig.feed(tone(FS, 0.1, 10 ** (-50 / 20), start=int(0.6 * FS)))
    assert rig.controller.driver(0) == "follow" and rig.plays(0)[0] == pytest.approx(knob_of(-50), abs=0.02)


def test_panic_turns_follow_off_everywhere(make_rig):
    rig = make_rig()
    rig.feed(tone(FS, 0.3, 10 ** (-50 / 20)))
    rig.controller.panic(source="osc")
    rig.feed(tone(FS, 0.3, 10 ** (-50 / 20), start=int(0.3 * FS)))
    assert [rig.controller.driver(c) for c in (0, 1)] == ["knobs", "knobs"]
    assert rig.plays(0)[0] == 0.0 and not rig.follower.is_on(0)


def test_a_lost_input_fades_out_then_follow_recovers_when_frames_return(make_rig):
    rig = make_rig(follow={"on_loss": "fade", "fade_s": 0.25})
    rig.feed(tone(FS, 0.4, 10 ** (-50 / 20)))
    rig.source.state, rig.source.reason = "lost", "device unplugged"
    rig.idle(0.1)
    assert rig.follower.lost and rig.follower.losses == 1
    assert "lost: device unplugged" in rig.follower.device_text()
    rig.idle(0.3)
    assert rig.plays(0)[0] == 0.0 and rig.controller.driver(0) == "follow"
    rig.source.state = "open"
    rig.feed(tone(FS, 0.4, 10 ** (-56 / 20)))
    assert not rig.follower.lost and rig.follower.recoveries == 1
    assert rig.plays(0)[0] == pytest.approx(knob_of(-56), abs=0.02)


def test_stray_blocks_while_the_input_says_it_is_lost_are_no_recovery(make_rig):
    """PortAudio on a dead JACK server still delivers a block now and then while serve's output retries:
    measured in tests/e2e/test_follow_loss_e2e.py, it made follow flap lost/back 22 times in one outage."""
    rig = make_rig(follow={"on_loss": "fade", "fade_s": 0.0})
    rig.feed(tone(FS, 0.4, 10 ** (-50 / 20)))
    rig.source.state, rig.source.reason = "retrying", "JACK server shut down"
    rig.idle(0.1)
    assert rig.follower.lost and rig.follower.losses == 1
    for k in range(5):  # a stray block every 100 ms, the state still "retrying"
        rig.feed(tone(FS, 128 / FS, 10 ** (-50 / 20), start=k * 128))
        rig.idle(0.1)
    assert rig.follower.lost and rig.follower.recoveries == 0 and rig.follower.losses == 1
    assert rig.follower.stray_frames == 5 * 128 and rig.plays(0)[0] == 0.0
    rig.source.state = "open"
    rig.feed(tone(FS, 0.4, 10 ** (-56 / 20)))
    assert not rig.follower.lost and rig.follower.recoveries == 1


def test_a_lost_input_holds_the_last_texture_when_asked(make_rig):
    rig = make_rig(follow={"on_loss": "hold"})
    rig.feed(tone(FS, 0.4, 10 ** (-50 / 20)))
    held = rig.plays(0)
    rig.source.state = "retrying"
    rig.idle(1.0)
    assert rig.follower.lost and rig.plays(0) == pytest.approx(held)


def test_an_input_that_stops_delivering_counts_as_lost(make_rig):
    rig = make_rig(follow={"fade_s": 0.0})
    rig.feed(tone(FS, 0.3, 10 ** (-50 / 20)))
    rig.idle(0.4)
    assert not rig.follower.lost  # within loss_timeout_s
    rig.idle(0.2)
    assert rig.follower.lost and rig.plays(0)[0] == 0.0


def test_a_worker_that_fell_behind_drops_the_stale_input_and_counts_it(make_rig):
    rig = make_rig()
    x = tone(FS, 0.5, 10 ** (-50 / 20))
    rig.source.write(x)  # half a second waits at once: far more than max_lag_s
    rig.follower.step()
    keep = int(rig.follower.max_block_s * FS)
    assert rig.follower.stale_frames == x.size - keep and rig.follower.stale_drops == 1
    assert rig.source.ring.available == 0


def test_onsets_lift_the_intensity_like_a_clip_transient(make_rig, rng):
    quiet = 3e-4 * rng.standard_normal(8000)
    burst = np.zeros(4800)
    burst[:48] = 1e-2 * rng.standard_normal(48)  # a 3 ms click, 30 dB over the floor
    peaks = {}
    for transients in (True, False):
        rig = make_rig(follow={"transients": transients})
        moves: list[float] = []
        rig.controller.subscribe(
            lambda e: moves.append(float(e.value)) if e.name == "intensity" and e.source == "follow" else None
        )
        rig.feed(quiet)
        start = len(moves)
        rig.feed(burst)
        peaks[transients] = max(moves[start:])
    assert peaks[True] > peaks[False] + 0.1  # the click is felt as a burst, not only as its level


def test_the_snapshot_and_trace_show_the_input_level_gate_and_knobs(make_rig):
    rig = make_rig()
    rig.feed(tone(FS, 1.0, 10 ** (-50 / 20)))
    snap = rig.follower.snapshot()
    assert snap["device"] == "fake input" and snap["state"] == "open" and snap["gate"] is True
    assert snap["level_db"] == pytest.approx(-50.0, abs=0.5)
    assert [r["label"] for r in snap["routes"]] == ["ch1", "ch2"]
    trace = rig.follower.history("ch1")["ch1"]
    times = np.array([p[0] for p in trace])
    assert len(trace) == pytest.approx(1.0 / HISTORY_STEP_S, abs=2)
    assert np.allclose(np.diff(times), HISTORY_STEP_S, atol=0.004)
    assert trace[-1][1] == pytest.approx(-50.0, abs=0.5) and trace[-1][2] == pytest.approx(knob_of(-50), abs=0.02)


def test_a_transient_jumps_then_decays_linearly_back_to_the_curve():
    from vibsynth.control.follow.transients import TransientEnvelope
    from vibsynth.dsp.follow.onsets import TRANSIENT_BOOST

    env = TransientEnvelope(1000.0, 0.04)  # 40 samples of decay
    assert env.value(0.3, 0) == 0.3 and not env.active
    assert env.trigger(0.4, 0.8, 100) == pytest.approx(0.4 + 0.8 * TRANSIENT_BOOST)
    assert env.value(0.3, 100) == pytest.approx(0.6)
    assert env.value(0.3, 120) == pytest.approx(0.45)  # halfway from 0.6 to the curve
    assert env.value(0.7, 130) == 0.7  # never below the curve
    assert env.value(0.3, 140) == 0.3 and not env.active
    assert env.trigger(0.9, 1.0, 200) == 1.0  # at most 1
    assert env.trigger(0.1, 0.1, 205, now=0.95) == 0.95  # a new onset takes over from the running decay


def test_an_input_that_has_not_started_yet_is_not_lost(make_rig):
    """A file waits for the output clock: no frame yet is not a loss, however long it takes."""
    rig = make_rig()
    rig.idle(2.0)
    assert not rig.follower.lost and rig.follower.losses == 0
    rig.feed(tone(FS, 0.2, 10 ** (-50 / 20)))
    rig.idle(0.6)
    assert rig.follower.lost and rig.follower.losses == 1
