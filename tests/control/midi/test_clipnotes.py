"""MIDI notes that play clips (``midi_clips``): velocity gain, note-off stop, sustain pedal, no stuck clips."""

from __future__ import annotations

import mido
import numpy as np
import pytest

from tests.control.midi.fakes import LoopPort, midi_settings
from vibsynth.app.midi_render import render_midi_file
from vibsynth.control import clips
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.controller import Controller
from vibsynth.control.midi.clipnotes import ClipNotes
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import MidiServer
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis
from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir
from vibsynth.settings.config import default_config_data
from vibsynth.settings.typed import settings_of

FS = 8000.0
BLOCK = 64
NOTE_MAP = {
    "velocity_curve": 2.0,
    "release_ms": 40.0,
    "notes": [
        {"note": 36, "clip": "impact", "note_off": "ignore"},
        {"notes": [48, 59], "clip": "rain", "loops": 0},
        {"note": 60, "clip": "heartbeat", "midi_channel": 10, "channels": [2], "gain": 0.5},
        {"note": 61, "clip": "no-such-clip"},
    ],
}


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=FS, loop_seconds=1.0, levels=15, seed=4))


def config_data(**midi_clips):
    data = default_config_data()
    data["audio"]["channels"] = 2
    data["midi_clips"].update(NOTE_MAP, **midi_clips)
    return data


class Rig:
    """A real engine, controller and clip player; the MIDI mapper as serve builds it."""

    def __init__(self, bank, tmp_path, **midi_clips) -> None:
        data = config_data(**midi_clips)
        self.engine = Engine(bank, channels=2, glide_s=0.0, max_block=BLOCK)
        self.controller = Controller(self.engine, initial_glide_s=0.0)
        self.player = ClipPlayer(self.controller, ClipLibrary(shipped_clips_dir(), tmp_path).get, start_margin_frames=0)
        clips.attach(self.controller, self.player)
        self.notes = ClipNotes.from_settings(settings_of(data).midi_clips, self.controller)
        self.mapper = MidiMapper(self.controller, midi_settings(data, 2), clip_notes=self.notes)

    def send(self, *msgs: mido.Message) -> None:
        for msg in msgs:
            assert self.mapper.handle(msg), msg

    def run(self, frames: int) -> None:
        end = self.engine.frame_position + frames
        while self.engine.frame_position < end:
            self.player.tick()
            self.engine.render(BLOCK)

    def name(self, channel: int) -> str | None:
        playing = self.player.playing(channel)
        return None if playing is None else playing.name

    def close(self) -> None:
        clips.detach(self.controller, self.player)


@pytest.fixture
def rig(bank, tmp_path):
    r = Rig(bank, tmp_path)
    yield r
    r.close()


def on(note: int, velocity: int = 100, channel: int = 0) -> mido.Message:
    return mido.Message("note_on", note=note, velocity=velocity, channel=channel)


def off(note: int, channel: int = 0) -> mido.Message:
    return mido.Message("note_off", note=note, channel=channel)


def cc(control: int, value: int, channel: int = 0) -> mido.Message:
    return mido.Message("control_change", control=control, value=value, channel=channel)


def test_a_note_plays_its_clip_with_a_velocity_gain_and_leaves_the_texture_alone(rig):
    rig.send(on(48, 64))
    playing = rig.player.playing(0)
    assert playing.name == "rain" and playing.loops == 0
    assert playing.gain == pytest.approx((64 / 127) ** 2.0)
    assert rig.name(1) == "rain"  # MIDI channel 1 maps to every actuator (midi.channel_map)
    assert not rig.mapper._act[0].held and rig.controller.driver(0) == "clip"
    rig.send(on(40))  # a note outside the map: the gate texture, under the clip
    assert rig.mapper._act[0].held and rig.controller.layer_targets("knobs", 0)[0] > 0


def test_note_off_stops_with_the_release_and_a_one_shot_plays_on(rig):
    rig.send(on(50))
    rig.run(800)
    rig.send(off(50))
    rig.run(800)
    assert rig.name(0) is None and rig.controller.driver(0) == "knobs"
    rig.send(on(36, 127))  # note_off: ignore
    assert rig.notes.release_all() == 0  # a vanished port leaves a one-shot playing too
    rig.send(off(36))
    rig.run(BLOCK)
    assert rig.name(0) == "impact"
    rig.run(int(0.4 * FS))
    assert rig.name(0) is None  # it ended on its own


def test_the_sustain_pedal_holds_note_offs_until_it_is_released(rig):
    rig.send(cc(64, 127), on(50), off(50))
    rig.run(1600)
    assert rig.name(0) == "rain"
    rig.send(on(52), off(52))  # re-pressed under the pedal: the new clip plays, the old stop waits
    rig.send(cc(64, 0))
    rig.run(800)
    assert rig.name(0) is None and rig.notes.counts["stopped"] == 1


def test_a_note_off_stops_only_the_clip_its_note_started(rig):
    rig.send(on(50))
    rig.run(800)
    rig.player.play("zipper", channels=[0])  # e.g. an OSC play takes channel 1 over
    rig.run(BLOCK)
    rig.send(off(50))
    rig.run(BLOCK)
    assert rig.name(0) == "zipper" and rig.name(1) is None  # channel 2 still had the note's clip: stopped


def test_an_entry_for_one_midi_channel_drives_its_own_actuators(rig):
    rig.send(on(60, 127, channel=9))  # MIDI channel 10: not in midi.channel_map, but the entry names actuator 2
    assert rig.name(1) == "heartbeat" and rig.name(0) is None
    assert rig.player.playing(1).gain == pytest.approx(0.5)
    rig.send(on(60, 127, channel=0))  # note 60 on channel 1 is not in the map: the gate texture
    assert rig.name(0) is None and rig.mapper._act[0].held


def test_all_notes_off_reset_and_a_vanished_port_leave_no_clip_playing(bank, tmp_path):
    rig = Rig(bank, tmp_path)
    try:
        rig.send(on(50))
        rig.send(cc(123, 0))
        rig.run(800)
        assert rig.name(0) is None and rig.name(1) is None
        rig.send(on(50, channel=0), on(60, channel=9))
        rig.send(cc(120, 0, channel=9))  # all sound off on MIDI channel 10: its clip stops, channel 1's plays on
        rig.run(800)
        assert rig.name(0) == "rain" and rig.name(1) is None and rig.player.stats.stops >= 2
        rig.send(mido.Message("reset"))  # a system reset: panic, every clip stops
        rig.run(BLOCK)
        assert rig.name(0) is None and rig.name(1) is None
        # a vanished port: held notes are released, one-shots play on
        port = LoopPort("pads")
        server = MidiServer(rig.mapper, port="pads", open_input=lambda n, v: port, input_names=lambda: ["pads"])
        server._open()
        port.send(on(50))
        port.send(on(60, channel=9))  # heartbeat on actuator 2 (a clip stopped by its note-off)
        for msg in server._port.iter_pending():
            server._feed(msg)
        assert rig.name(0) == "rain" and rig.name(1) == "heartbeat"
        server._disconnected()
        rig.run(800)
        assert rig.name(0) is None and rig.name(1) is None and server.disconnects == 1
    finally:
        rig.close()


def test_unknown_clips_and_a_missing_player_are_counted_not_raised(rig):
    rig.send(on(61))
    assert rig.notes.counts["midi_clip"] == 1 and "unknown clip 'no-such-clip'" in rig.notes.last_error
    assert rig.controller.error_counts["midi_clip"] == 1 and rig.name(0) is None
    clips.detach(rig.controller, rig.player)
    rig.send(on(50))
    assert rig.controller.error_counts["midi_no_clip_player"] == 1


def test_render_midi_plays_the_clip_notes_offline(bank, tmp_path):
    mid = mido.MidiFile(ticks_per_beat=480)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.MetaMessage("set_tempo", tempo=500000, time=0))  # 960 ticks per second
    track.append(mido.Message("note_on", note=50, velocity=127, time=480))  # 0.5 s
    track.append(mido.Message("note_off", note=50, time=960))  # 1.5 s
    path = tmp_path / "pad.mid"
    mid.save(path)
    data = config_data()

    engine = Engine(bank, channels=2, ceiling_db=-40.0, glide_s=0.02)
    x, fs = render_midi_file(
        path,
        settings=settings_of(data),
        engine=engine,
        seconds=2.0,
        clips=ClipLibrary(shipped_clips_dir(), tmp_path),
    )
    signal = x[:, 0].astype(np.float64)
    assert np.max(np.abs(signal[: int(0.5 * FS)])) == 0.0  # nothing before the note
    assert intensity_level_db(signal[int(0.6 * FS) : int(1.4 * FS)], fs=FS) > -80.0  # the rain plays
    assert np.max(np.abs(signal[int(1.6 * FS) :])) == 0.0  # stopped at the note-off (40 ms release)
