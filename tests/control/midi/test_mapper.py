"""Unit tests of the MIDI mapping: mido messages through a test port into the real Controller."""

from __future__ import annotations

from dataclasses import dataclass

import mido
import numpy as np
import pytest

from tests.control.midi.fakes import LoopPort, midi_settings
from vibsynth.control.controller import Controller, KnobLimits
from vibsynth.control.midi.bindings import Binding, parse_bindings, parse_channel_map, scale_raw
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import MidiServer, resolve_port_name
from vibsynth.engine.commands import Panic, SetKnob
from vibsynth.errors import ConfigError, DeviceError
from vibsynth.settings.config import default_config_data


# ---------------------------------------------------------------------- fakes
class FakeEngine:
    """Records commands; what Controller needs of an engine."""

    def __init__(self, channels: int = 1, fs: float = 48000.0) -> None:
        self.channels = channels
        self.fs = fs
        self.commands: list = []

    def submit(self, command) -> int:
        self.commands.append(command)
        return len(self.commands)

    @property
    def applied_seq(self) -> int:
        return len(self.commands)

    @property
    def frame_position(self) -> int:
        return 0


@dataclass
class FakePreset:
    name: str
    intensity: float
    balance: float
    glide_ms: float | None = None
    program: int | None = None


class FakePresets:
    def __init__(self, presets: list[FakePreset]) -> None:
        self._p = {p.name: p for p in presets}

    def names(self) -> list[str]:
        return list(self._p)

    def get(self, name: str) -> FakePreset:
        return self._p[name]

    def by_program(self, n: int):
        return next((p for p in self._p.values() if p.program == n), None)


def make(channels: int = 1, presets=None, **midi) -> tuple[MidiMapper, Controller, FakeEngine, LoopPort]:
    data = default_config_data()
    data["midi"].update(midi)
    engine = FakeEngine(channels)
    resolver = presets.get if presets is not None else None
    controller = Controller(engine, limits=KnobLimits(-3.5, 3.5), preset_resolver=resolver)
    settings = midi_settings(data, channels)
    mapper = MidiMapper(controller, settings, presets=presets, clock=lambda: 0.0)
    return mapper, controller, engine, LoopPort()


def play(mapper: MidiMapper, port: LoopPort, *msgs: mido.Message) -> None:
    """Send messages through the test port and feed what comes out to the mapper."""
    for m in msgs:
        port.send(m)
    for m in port.iter_pending():
        mapper.handle(m)


def cc(control: int, value: int, channel: int = 0) -> mido.Message:
    return mido.Message("control_change", control=control, value=value, channel=channel)


def on(note: int, velocity: int = 127, channel: int = 0) -> mido.Message:
    return mido.Message("note_on", note=note, velocity=velocity, channel=channel)


def off(note: int, channel: int = 0) -> mido.Message:
    return mido.Message("note_off", note=note, channel=channel)


def knob(controller: Controller, name: str, channel: int = 0) -> float:
    return float(controller.get(name, channel))


def knob_cmds(engine: FakeEngine, name: str) -> list[SetKnob]:
    return [c for c in engine.commands if isinstance(c, SetKnob) and c.name == name]


# ---------------------------------------------------------------------- default map
def test_cc11_sets_intensity_in_continuous_mode():
    mapper, ctl, engine, port = make(mode="continuous")
    play(mapper, port, cc(11, 127))
    assert knob(ctl, "intensity") == 1.0
    play(mapper, port, cc(11, 0))
    assert knob(ctl, "intensity") == 0.0
    play(mapper, port, cc(11, 64))
    assert knob(ctl, "intensity") == pytest.approx(64 / 127)


@pytest.mark.parametrize("control", [74, 1])
def test_cc74_and_cc1_map_balance_over_live_range_centred(control):
    mapper, ctl, engine, port = make()
    play(mapper, port, cc(control, 0))
    assert knob(ctl, "balance") == pytest.approx(-3.5)
    play(mapper, port, cc(control, 127))
    assert knob(ctl, "balance") == pytest.approx(3.5)
    play(mapper, port, cc(control, 64))
    assert knob(ctl, "balance") == 0.0
    play(mapper, port, cc(control, 96))
    assert knob(ctl, "balance") == pytest.approx(3.5 * 32 / 63)


def test_balance_sweep_is_monotonic_and_in_range():
    mapper, ctl, engine, port = make()
    values = []
    for v in range(128):
        play(mapper, port, cc(74, v))
        values.append(knob(ctl, "balance"))
    assert np.all(np.diff(values) > 0)
    assert values[0] == -3.5 and values[-1] == 3.5


def test_pitch_bend_offsets_balance_and_clamps():
    mapper, ctl, engine, port = make(pitch_bend_range=0.5)
    play(mapper, port, cc(74, 64))
    play(mapper, port, mido.Message("pitchwheel", pitch=8191))
    assert knob(ctl, "balance") == pytest.approx(0.5)
    play(mapper, port, mido.Message("pitchwheel", pitch=-8192))
    assert knob(ctl, "balance") == pytest.approx(-0.5)
    play(mapper, port, cc(74, 0))  # -3.5 - 0.5 would be out of range: clamped, no error
    assert knob(ctl, "balance") == -3.5
    assert not ctl.error_counts
    play(mapper, port, mido.Message("pitchwheel", pitch=0))
    assert knob(ctl, "balance") == -3.5


def test_pitch_bend_starts_from_current_balance():
    mapper, ctl, engine, port = make(pitch_bend_range=1.0)
    ctl.set_knob("balance", 1.25)
    play(mapper, port, mido.Message("pitchwheel", pitch=8191))
    assert knob(ctl, "balance") == pytest.approx(2.25)


# ---------------------------------------------------------------------- 14-bit and NRPN
def test_14bit_cc_pair_decodes_msb_lsb():
    mapper, ctl, engine, port = make(mapping={"intensity": [{"cc": 11}], "balance": [{"cc": 1}]})
    play(mapper, port, cc(1, 64), cc(33, 0))
    assert knob(ctl, "balance") == 0.0  # 8192 is the 14-bit centre
    play(mapper, port, cc(1, 100), cc(33, 77))
    raw = (100 << 7) | 77
    assert knob(ctl, "balance") == pytest.approx(3.5 * (raw - 8192) / (16383 - 8192))
    play(mapper, port, cc(1, 127), cc(33, 127))
    assert knob(ctl, "balance") == 3.5
    # the MSB resets the LSB: 101 alone means 101 * 128
    play(mapper, port, cc(1, 101))
    assert knob(ctl, "balance") == pytest.approx(3.5 * (101 * 128 - 8192) / (16383 - 8192))


def test_14bit_resolution_is_finer_than_7bit():
    mapper, ctl, engine, port = make(mode="continuous", mapping={"intensity": [{"cc": 7}]})
    seen = set()
    for lsb in range(0, 128, 8):
        play(mapper, port, cc(7, 50), cc(39, lsb))
        seen.add(round(knob(ctl, "intensity"), 9))
    assert len(seen) == 16
    assert max(seen) - min(seen) < 1 / 127


def test_nrpn_per_channel_with_default_numbers():
    mapper, ctl, engine, port = make(channels=2, mode="continuous", channel_map={1: [1], 2: [2]})
    # channel 1 selects the intensity NRPN (1, 0), channel 2 the balance NRPN (1, 1)
    play(mapper, port, cc(99, 1, 0), cc(98, 0, 0), cc(99, 1, 1), cc(98, 1, 1))
    play(mapper, port, cc(6, 127, 0), cc(38, 127, 0))
    assert knob(ctl, "intensity", 0) == 1.0
    play(mapper, port, cc(6, 32, 1), cc(38, 0, 1))
    assert knob(ctl, "balance", 1) == pytest.approx(-3.5 * (8192 - 4096) / 8192)
    assert knob(ctl, "intensity", 1) == 0.0  # channel 2 did not touch intensity
    # data entry follows each channel's own active parameter
    play(mapper, port, cc(6, 0, 0), cc(38, 0, 0))
    assert knob(ctl, "intensity", 0) == 0.0
    assert knob(ctl, "balance", 1) == pytest.approx(-1.75)


def test_nrpn_msb_only_device_is_7bit():
    mapper, ctl, engine, port = make(mode="continuous")
    play(mapper, port, cc(99, 1), cc(98, 0), cc(6, 127))
    assert knob(ctl, "intensity") == 1.0


def test_rpn_deselects_nrpn_and_unknown_nrpn_is_counted():
    mapper, ctl, engine, port = make(mode="continuous")
    play(mapper, port, cc(99, 1), cc(98, 0), cc(101, 0), cc(100, 0), cc(6, 100))
    assert knob(ctl, "intensity") == 0.0
    play(mapper, port, cc(99, 5), cc(98, 5), cc(6, 100))
    assert knob(ctl, "intensity") == 0.0
    assert ctl.error_counts["midi_unknown_nrpn"] == 2


# ---------------------------------------------------------------------- notes
def test_gate_note_on_velocity_curve_and_release_glide():
    mapper, ctl, engine, port = make(velocity_curve=2.0, release_ms=300.0)
    play(mapper, port, on(60, 64))
    assert knob(ctl, "intensity") == pytest.approx((64 / 127) ** 2)
    play(mapper, port, off(60))
    assert knob(ctl, "intensity") == 0.0
    assert knob_cmds(engine, "intensity")[-1].glide_s == pytest.approx(0.3)


def test_note_on_velocity_zero_is_note_off():
    mapper, ctl, engine, port = make()
    play(mapper, port, on(60, 100))
    assert knob(ctl, "intensity") == pytest.approx(100 / 127)  # sounding first: the 0 below is a release
    play(mapper, port, on(60, 0))
    assert knob(ctl, "intensity") == 0.0
    assert knob_cmds(engine, "intensity")[-1].glide_s == pytest.approx(0.15)  # the release glide, as a note-off


def test_stacked_notes_sound_until_last_released():
    mapper, ctl, engine, port = make()
    play(mapper, port, on(60, 127), on(64, 64), on(67, 100))
    assert knob(ctl, "intensity") == pytest.approx(100 / 127)  # last note priority
    play(mapper, port, off(67))
    assert knob(ctl, "intensity") == pytest.approx(64 / 127)
    play(mapper, port, off(60))
    assert knob(ctl, "intensity") == pytest.approx(64 / 127)
    play(mapper, port, off(64))
    assert knob(ctl, "intensity") == 0.0


def test_expression_scales_held_note_and_does_not_start_sound():
    mapper, ctl, engine, port = make()
    play(mapper, port, cc(11, 127))
    assert knob_cmds(engine, "intensity") == []  # gate mode: no note, no sound
    play(mapper, port, on(60, 127), cc(11, 64))
    assert knob(ctl, "intensity") == pytest.approx(64 / 127)


def test_continuous_mode_ignores_notes():
    mapper, ctl, engine, port = make(mode="continuous")
    play(mapper, port, cc(11, 50), on(60, 127), off(60))
    assert knob(ctl, "intensity") == pytest.approx(50 / 127)
    assert mapper.counts["note_ignored"] == 2


def test_channel_pressure_and_poly_aftertouch_drive_intensity():
    mapper, ctl, engine, port = make()
    play(mapper, port, on(60, 20), mido.Message("aftertouch", value=100))
    assert knob(ctl, "intensity") == pytest.approx(100 / 127)
    play(mapper, port, mido.Message("polytouch", note=60, value=120))
    assert knob(ctl, "intensity") == pytest.approx(120 / 127)
    play(mapper, port, mido.Message("polytouch", note=61, value=127))  # not held: no effect
    assert knob(ctl, "intensity") == pytest.approx(120 / 127)
    mapper2, ctl2, _, port2 = make(mode="continuous")
    play(mapper2, port2, mido.Message("aftertouch", value=90))
    assert knob(ctl2, "intensity") == pytest.approx(90 / 127)


def test_mpe_member_channels_drive_their_own_actuators():
    mapper, ctl, engine, port = make(channels=2, mpe=True)
    play(mapper, port, on(60, 100, channel=1), on(62, 50, channel=2))
    assert knob(ctl, "intensity", 0) == pytest.approx(100 / 127)
    assert knob(ctl, "intensity", 1) == pytest.approx(50 / 127)
    play(mapper, port, cc(74, 127, channel=2), mido.Message("aftertouch", value=10, channel=1))
    assert knob(ctl, "balance", 1) == 3.5
    assert knob(ctl, "balance", 0) == 0.0
    assert knob(ctl, "intensity", 0) == pytest.approx(10 / 127)  # MPE: pressure replaces velocity
    play(mapper, port, off(60, channel=1))
    assert knob(ctl, "intensity", 0) == 0.0
    assert knob(ctl, "intensity", 1) == pytest.approx(50 / 127)
    # member channels 4 and 2 share actuator 1 (round robin): it sounds until both are up
    play(mapper, port, on(70, 127, channel=3))
    play(mapper, port, off(62, channel=2))
    assert knob(ctl, "intensity", 0) == 1.0
    assert knob(ctl, "intensity", 1) == 0.0


def test_channel_map_routes_and_unmapped_channels_are_counted():
    mapper, ctl, engine, port = make(channels=3, channel_map={1: "all", 2: [3], 3: [1, 2]})
    play(mapper, port, cc(74, 127, channel=1))
    assert [knob(ctl, "balance", c) for c in range(3)] == [0.0, 0.0, 3.5]
    play(mapper, port, cc(74, 0, channel=2))
    assert [knob(ctl, "balance", c) for c in range(3)] == [-3.5, -3.5, 3.5]
    play(mapper, port, cc(74, 64, channel=0))
    assert [knob(ctl, "balance", c) for c in range(3)] == [0.0, 0.0, 0.0]
    play(mapper, port, cc(74, 0, channel=9))
    assert ctl.error_counts["midi_unmapped_channel"] == 1


def test_default_channel_1_drives_all_actuators():
    mapper, ctl, engine, port = make(channels=4)
    play(mapper, port, on(60, 127))
    assert [knob(ctl, "intensity", c) for c in range(4)] == [1.0] * 4
    # one command for all four channels, not four
    assert len(knob_cmds(engine, "intensity")) == 1 and knob_cmds(engine, "intensity")[0].channels is None


# ---------------------------------------------------------------------- silence
@pytest.mark.parametrize("control", [120, 123])
def test_all_notes_off_silences_immediately(control):
    mapper, ctl, engine, port = make()
    play(mapper, port, on(60), on(61))
    assert knob(ctl, "intensity") == 1.0
    play(mapper, port, cc(control, 0))
    assert knob(ctl, "intensity") == 0.0
    assert isinstance(engine.commands[-1], Panic)
    # the notes are forgotten: their late note-offs do not revive anything
    play(mapper, port, off(60))
    assert knob(ctl, "intensity") == 0.0


def test_all_notes_off_on_a_subset_fades_only_those_channels():
    mapper, ctl, engine, port = make(channels=2, channel_map={1: [1], 2: [2]})
    play(mapper, port, on(60, channel=0), on(60, channel=1), cc(123, 0, channel=1))
    assert knob(ctl, "intensity", 0) == 1.0 and knob(ctl, "intensity", 1) == 0.0
    last = engine.commands[-1]
    assert isinstance(last, SetKnob) and last.channels == (1,) and last.glide_s == pytest.approx(0.01)


@pytest.mark.parametrize("kind", ["reset", "stop"])
def test_reset_and_stop_silence_everything(kind):
    mapper, ctl, engine, port = make(channels=2, mode="continuous")
    play(mapper, port, cc(11, 127))
    assert [knob(ctl, "intensity", c) for c in range(2)] == [1.0, 1.0]
    play(mapper, port, mido.Message(kind))
    assert [knob(ctl, "intensity", c) for c in range(2)] == [0.0, 0.0]
    assert isinstance(engine.commands[-1], Panic)


def test_reset_all_controllers_clears_bend_and_expression():
    mapper, ctl, engine, port = make()
    play(mapper, port, on(60, 127), cc(11, 0), mido.Message("pitchwheel", pitch=8191))
    assert knob(ctl, "intensity") == 0.0 and knob(ctl, "balance") == pytest.approx(0.5)
    play(mapper, port, cc(121, 0))
    assert knob(ctl, "intensity") == 1.0 and knob(ctl, "balance") == 0.0


def test_release_all_after_disconnect_leaves_no_stuck_note():
    mapper, ctl, engine, port = make(channels=2, channel_map={1: [1], 2: [2]})
    play(mapper, port, on(60, channel=0), on(61, channel=0))
    assert mapper.release_all() == (0,)
    assert knob(ctl, "intensity", 0) == 0.0
    assert knob_cmds(engine, "intensity")[-1].glide_s == pytest.approx(0.15)


# ---------------------------------------------------------------------- program change
def test_program_change_by_program_field_then_sorted_order():
    presets = FakePresets(
        [FakePreset("zeta", 0.8, 1.0, program=5), FakePreset("alpha", 0.5, -1.0), FakePreset("beta", 0.6, 2.0)]
    )
    mapper, ctl, engine, port = make(presets=presets, mode="continuous")
    play(mapper, port, mido.Message("program_change", program=5))
    assert (knob(ctl, "intensity"), knob(ctl, "balance")) == (0.8, 1.0)
    assert ctl.get("preset") == "zeta"
    play(mapper, port, mido.Message("program_change", program=1))  # sorted: alpha, beta, zeta
    assert (knob(ctl, "intensity"), knob(ctl, "balance")) == (0.6, 2.0)
    play(mapper, port, mido.Message("program_change", program=99))
    assert ctl.error_counts["midi_unknown_program"] == 1
    assert knob(ctl, "balance") == 2.0


def test_program_change_in_gate_mode_sets_balance_and_note_scale_only():
    presets = FakePresets([FakePreset("soft", 0.5, -2.0)])
    mapper, ctl, engine, port = make(presets=presets)
    play(mapper, port, mido.Message("program_change", program=0))
    assert knob(ctl, "balance") == -2.0
    assert knob(ctl, "intensity") == 0.0  # no note held: stays silent
    play(mapper, port, on(60, 127))
    assert knob(ctl, "intensity") == 0.5


def test_program_change_without_presets_is_counted():
    mapper, ctl, engine, port = make()
    play(mapper, port, mido.Message("program_change", program=0))
    assert ctl.error_counts["midi_unknown_program"] == 1


# ---------------------------------------------------------------------- bad input
def test_bad_and_unknown_messages_are_ignored_and_counted():
    mapper, ctl, engine, port = make(mode="continuous")
    play(
        mapper,
        port,
        mido.Message("sysex", data=[1, 2, 3, 4]),
        cc(20, 5),
        cc(64, 127),
        mido.Message("clock"),
        mido.Message("active_sensing"),
    )
    assert mapper.handle_bytes([0xB0, 200, 3]) is False  # data byte > 127
    assert mapper.handle_bytes([0x93]) is False  # truncated
    assert mapper.handle_bytes([]) is False
    assert engine.commands == []
    assert ctl.error_counts == {"midi_sysex": 1, "midi_unknown_cc": 2, "midi_bad": 3}
    # still alive afterwards
    play(mapper, port, cc(11, 127))
    assert knob(ctl, "intensity") == 1.0


def test_fuzzed_bytes_never_raise_and_keep_knobs_in_range():
    rng = np.random.default_rng(1234)
    mapper, ctl, engine, port = make(channels=2, mpe=True, pitch_bend_range=5.0)
    for _ in range(3000):
        n = int(rng.integers(1, 4))
        data = [int(rng.integers(0x80, 0x100))] + [int(x) for x in rng.integers(0, 128, n - 1)]
        mapper.handle_bytes(data)
    for state in ctl.state():
        assert 0.0 <= state.intensity <= 1.0
        assert -3.5 <= state.balance <= 3.5


def test_invert_binding():
    mapper, ctl, engine, port = make(mode="continuous", mapping={"intensity": [{"cc": 11, "invert": True}]})
    play(mapper, port, cc(11, 0))
    assert knob(ctl, "intensity") == 1.0
    play(mapper, port, cc(11, 127))
    assert knob(ctl, "intensity") == 0.0


def test_values_are_clamped_before_the_controller():
    mapper, ctl, engine, port = make(
        mode="continuous",
        mapping={"intensity": [{"cc": 11, "range": [-1, 2]}], "balance": [{"cc": 74, "range": [-10, 10]}]},
    )
    play(mapper, port, cc(11, 127), cc(74, 0))
    assert knob(ctl, "intensity") == 1.0 and knob(ctl, "balance") == -3.5
    assert not ctl.error_counts


# ---------------------------------------------------------------------- learn (in memory)
def test_learn_binds_next_controller_and_moves_it_between_knobs():
    mapper, ctl, engine, port = make(mode="continuous")
    learned = []
    mapper.learn("intensity", lambda b, all_: learned.append((b, all_)))
    play(mapper, port, cc(1, 127))  # the mod wheel now drives intensity, not balance
    assert learned[0][0] == Binding("intensity", cc=1)
    assert knob(ctl, "intensity") == 1.0 and knob(ctl, "balance") == 0.0
    assert not any(b.knob == "balance" and b.cc == 1 for b in mapper.bindings)
    play(mapper, port, cc(11, 0))  # the old binding still works
    assert knob(ctl, "intensity") == 0.0
    assert mapper.learning is None


def test_learn_nrpn():
    mapper, ctl, engine, port = make(mode="continuous")
    mapper.learn("balance")
    play(mapper, port, cc(99, 3), cc(98, 4), cc(6, 127), cc(38, 127))
    assert mapper.bindings[0] == Binding("balance", nrpn=3 * 128 + 4)
    assert knob(ctl, "balance") == 3.5


# ---------------------------------------------------------------------- config parsing
def test_config_errors_name_the_key():
    with pytest.raises(ConfigError, match="midi.mapping.volume"):
        parse_bindings({"volume": [{"cc": 7}]})
    with pytest.raises(ConfigError, match=r"midi.mapping.balance\[0\].cc"):
        parse_bindings({"balance": [{"cc": 200}]})
    with pytest.raises(ConfigError, match="reserved"):
        parse_bindings({"balance": [{"cc": 6}]})
    with pytest.raises(ConfigError, match="channel_map.17"):
        parse_channel_map({17: "all"}, 2)
    with pytest.raises(ConfigError, match="channel_map.1"):
        parse_channel_map({1: [3]}, 2)
    data = default_config_data()
    data["midi"]["mode"] = "drone"
    with pytest.raises(ConfigError, match="midi.mode"):
        midi_settings(data, 1)


def test_channel_map_defaults_and_omni():
    assert parse_channel_map({1: "all"}, 2) == {0: (0, 1)}
    assert parse_channel_map(None, 1) == {c: (0,) for c in range(16)}
    mpe = parse_channel_map({1: "all"}, 3, mpe=True)
    assert mpe[0] == (0, 1, 2) and mpe[1] == (0,) and mpe[3] == (2,) and mpe[4] == (0,)


def test_scale_raw_centred_and_linear():
    assert scale_raw(64, 127, -2, 2, centred=True) == 0.0
    assert scale_raw(8192, 16383, -2, 2, centred=True) == 0.0
    assert scale_raw(0, 127, -2, 3, centred=True) == -2.0
    assert scale_raw(127, 127, -2, 3, centred=True) == 3.0
    assert scale_raw(127, 127, 0.2, 0.8, centred=True) == pytest.approx(0.8)
    assert scale_raw(300, 127, 0, 1, centred=False) == 1.0


# ---------------------------------------------------------------------- adaptive smoothing
def test_cc_glide_follows_message_spacing_at_frames():
    mapper, ctl, engine, port = make(mode="continuous")
    fs = engine.fs
    for i, v in enumerate(range(0, 128, 16)):
        mapper.handle(cc(11, v), at_frame=int(i * 0.05 * fs))
    glides = [c.glide_s for c in knob_cmds(engine, "intensity")]
    assert glides[0] is None  # first move: the channel glide
    assert glides[1:] == pytest.approx([0.05] * (len(glides) - 1))
    frames = [c.at_frame for c in knob_cmds(engine, "intensity")]
    assert frames == [int(i * 0.05 * fs) for i in range(len(frames))]


# ---------------------------------------------------------------------- server with a fake port
class FakeInput(LoopPort):
    pass


def test_server_feeds_port_and_releases_notes_on_disconnect():
    mapper, ctl, engine, _ = make()
    ports: dict[str, FakeInput] = {}
    names = ["Keys A", "Pad B"]

    def open_input(name, virtual):
        ports[name] = FakeInput(name)
        return ports[name]

    server = MidiServer(
        mapper, port="pad", open_input=open_input, input_names=lambda: list(names), reconnect_interval_s=60.0
    )
    server._open()
    assert server._port_name == "Pad B"
    ports["Pad B"].send(on(60, 127))
    for m in server._port.iter_pending():
        server._feed(m)
    assert knob(ctl, "intensity") == 1.0
    names.remove("Pad B")
    server._disconnected()
    assert knob(ctl, "intensity") == 0.0 and server.disconnects == 1 and server._port is None
    assert "Pad B" in server.describe()


def test_resolve_port_name():
    names = ["Midi Through:0", "Keystation 49:0", "vibsynth:vibsynth"]
    assert resolve_port_name("keystation", names) == "Keystation 49:0"
    assert resolve_port_name(2, names) == "vibsynth:vibsynth"
    assert resolve_port_name("1", names) == "Keystation 49:0"
    with pytest.raises(DeviceError, match="no MIDI input matches"):
        resolve_port_name("nanoKONTROL", names)
    with pytest.raises(DeviceError, match="index 5"):
        resolve_port_name(5, names)
