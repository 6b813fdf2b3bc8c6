"""MIDI controllers bound to source coordinates (``sources.midi``)."""

from __future__ import annotations

import mido
import pytest

from tests.control.osc.fakes import make_controller
from tests.control.spatial.rig import Clock, make_mixer
from vibsynth.control import spatial
from vibsynth.control.midi.bindings import MidiSettings, parse_bindings
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.spatial.midi import PositionControllers
from vibsynth.settings.config import load_config

CONFIG = {
    "sources.midi": [
        {"source": 1, "x": {"cc": 20, "range": [-0.1, 0.1]}, "y": {"cc": 21, "range": [0.0, 0.2]}},
        {"source": 2, "x": {"cc": 22, "channel": 2}},
    ]
}


@pytest.fixture
def rig(basis):
    ctl = make_controller(channels=4)
    mixer = make_mixer(ctl, basis, clock=Clock())
    config = load_config(overrides=CONFIG, env={}, user_file=False)
    mapper = MidiMapper(ctl, MidiSettings(mode="continuous", bindings=parse_bindings({"balance": [{"cc": 74}]})))
    mapper.positions = PositionControllers.from_settings(config.settings.sources.midi, ctl)
    spatial.attach(ctl, mixer)
    yield ctl, mixer, mapper
    spatial.detach(ctl, mixer)


def target(mixer, k):
    return mixer.read(lambda table, now: table.view(k - 1, now).target)


def cc(control, value, channel=0):
    return mido.Message("control_change", control=control, value=value, channel=channel)


def test_two_controllers_move_a_source_in_x_and_y(rig):
    ctl, mixer, mapper = rig
    assert mapper.handle(cc(20, 127)) and mapper.handle(cc(21, 0))
    assert target(mixer, 1) == pytest.approx((0.1, 0.0, 0.0))
    mapper.handle(cc(20, 0))
    mapper.handle(cc(21, 127))
    assert target(mixer, 1) == pytest.approx((-0.1, 0.2, 0.0))
    mapper.handle(cc(20, 64))
    assert target(mixer, 1)[0] == pytest.approx(-0.1 + 0.2 * 64 / 127)


def test_a_binding_on_one_midi_channel_ignores_the_others(rig):
    """Channel 2 drives no actuator (midi.channel_map): its source controllers work all the same."""
    ctl, mixer, mapper = rig
    mapper.handle(cc(22, 127, channel=0))  # not bound on channel 1: an unknown CC
    assert target(mixer, 2) == (0.0, 0.0, 0.0) and ctl.error_counts == {"midi_unknown_cc": 1}
    mapper.handle(cc(74, 127, channel=1))  # a knob controller on an unmapped channel is refused as before
    assert ctl.error_counts == {"midi_unknown_cc": 1, "midi_unmapped_channel": 1}
    mapper.handle(cc(22, 127, channel=1))
    assert target(mixer, 2) == pytest.approx((0.1, 0.0, 0.0))


def test_knob_controllers_still_move_the_knobs(rig):
    ctl, mixer, mapper = rig
    mapper.handle(cc(74, 127))
    assert ctl.get("balance", 0) == pytest.approx(3.5)
    assert target(mixer, 1) == (0.0, 0.0, 0.0)


def test_learn_does_not_take_a_source_controller(rig):
    ctl, mixer, mapper = rig
    mapper.learn("intensity")
    mapper.handle(cc(20, 100))
    assert mapper.learning == "intensity"
    mapper.handle(cc(30, 100))
    assert mapper.learning is None and any(b.cc == 30 and b.knob == "intensity" for b in mapper.bindings)


def test_without_a_layout_the_moves_are_counted_and_dropped(basis):
    ctl = make_controller(channels=4)
    config = load_config(overrides=CONFIG, env={}, user_file=False)
    positions = PositionControllers.from_settings(config.settings.sources.midi, ctl)
    assert positions.handle(0, 20, 127) is True
    assert positions.refused == 1 and ctl.error_counts == {"midi_no_layout": 1}
    assert positions.handle(0, 99, 127) is False
    assert PositionControllers.from_settings(load_config(env={}, user_file=False).settings.sources.midi, ctl) is None
