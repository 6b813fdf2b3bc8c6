"""Live Follow's gain from MIDI: a bound controller moves it, MIDI learn binds one, without follow it is counted."""

from __future__ import annotations

import mido
import pytest

from vibsynth.control import follow
from vibsynth.control.midi.bindings import FOLLOW_GAIN_RANGE_DB, MidiSettings, parse_bindings
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.settings.models_config import VibsynthConfig


def cc(control: int, value: int) -> mido.Message:
    return mido.Message("control_change", control=control, value=value)


@pytest.fixture
def rig(make_rig):
    rig = make_rig()
    follow.attach(rig.controller, rig.follower)
    yield rig
    follow.detach(rig.controller, rig.follower)


def test_a_bound_controller_moves_the_gain_over_its_range(rig):
    bindings = parse_bindings({"follow_gain": [{"cc": 7}], "intensity": [{"cc": 8, "range": [0, 1]}]}, None)
    mapper = MidiMapper(rig.controller, MidiSettings(mode="continuous", bindings=bindings, cc_glide_max_s=0.0))
    mapper.handle(cc(7, 127))
    assert rig.follower.gain_db == FOLLOW_GAIN_RANGE_DB[1]
    mapper.handle(cc(7, 0))
    assert rig.follower.gain_db == FOLLOW_GAIN_RANGE_DB[0]
    ranged = parse_bindings({"follow_gain": [{"cc": 7, "range": [-6, 6]}]}, None)
    mapper.set_bindings(ranged)
    mapper.handle(cc(7, 127))
    assert rig.follower.gain_db == 6.0


def test_midi_learn_binds_the_next_controller_to_the_gain(rig):
    mapper = MidiMapper(rig.controller, MidiSettings(mode="continuous", bindings=(), cc_glide_max_s=0.0))
    mapper.learn("follow_gain")
    mapper.handle(cc(21, 127))
    assert [(b.knob, b.cc) for b in mapper.bindings] == [("follow_gain", 21)]
    assert rig.follower.gain_db == FOLLOW_GAIN_RANGE_DB[1]


def test_without_follow_the_gain_controller_is_counted_and_nothing_moves(make_rig):
    rig = make_rig()
    mapper = MidiMapper(rig.controller, MidiSettings(bindings=parse_bindings({"follow_gain": [{"cc": 7}]}, None)))
    mapper.handle(cc(7, 100))
    assert mapper.counts["midi_no_follow"] == 1 and rig.controller.error_counts == {"midi_no_follow": 1}
    assert rig.follower.gain_db == 0.0


def test_the_config_takes_follow_gain_bindings():
    settings = VibsynthConfig.model_validate({"midi": {"mapping": {"follow_gain": [{"cc": 7, "range": [-12, 12]}]}}})
    assert settings.midi.mapping.follow_gain[0].cc == 7
