"""The MIDI input: python-rtmidi opened and polled through its public API, mido's public API otherwise."""

from __future__ import annotations

import time
import types

import mido
import pytest

from tests.control.midi.fakes import FakeEngine, midi_settings
from vibsynth.control.controller import Controller
from vibsynth.control.midi import server as midi_server
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import VIRTUAL_PORT_NAME, MidiServer, RtMidiInput, rtmidi_module
from vibsynth.settings.config import default_config_data
from vibsynth.settings.typed import settings_of


class FakeMidiIn:
    """python-rtmidi's MidiIn: records every call; ``queue`` is its C++ message queue."""

    made: list[FakeMidiIn] = []
    ports = ["Midi Through:0", "Keystation 49:0"]

    def __init__(self, rtapi=0, name=None) -> None:
        self.rtapi, self.client_name = rtapi, name
        self.calls: list[tuple] = []
        self.queue: list[tuple[list[int], float]] = []
        FakeMidiIn.made.append(self)

    def get_ports(self):
        return list(FakeMidiIn.ports)

    def open_port(self, index):
        self.calls.append(("open_port", index))

    def open_virtual_port(self, name):
        self.calls.append(("open_virtual_port", name))

    def ignore_types(self, sysex=True, timing=True, active_sense=True):
        self.calls.append(("ignore_types", sysex, timing, active_sense))

    def get_current_api(self):
        return self.rtapi

    def get_message(self):
        return self.queue.pop(0) if self.queue else None

    def set_callback(self, fn, data=None):  # what mido's port does: Python in the backend's thread
        self.calls.append(("set_callback",))

    def close_port(self):
        self.calls.append(("close_port",))

    def delete(self):
        self.calls.append(("delete",))


FAKE_RTMIDI = types.SimpleNamespace(
    API_UNSPECIFIED=0,
    API_LINUX_ALSA=2,
    API_UNIX_JACK=3,
    MidiIn=FakeMidiIn,
    get_api_name=lambda api: {0: "unspecified", 2: "alsa", 3: "jack"}[api],
)


@pytest.fixture
def fake_rtmidi(monkeypatch):
    FakeMidiIn.made = []
    monkeypatch.setattr(midi_server, "rtmidi_module", lambda: FAKE_RTMIDI)
    backend = types.SimpleNamespace(name="mido.backends.rtmidi", api="UNIX_JACK")
    monkeypatch.setattr(midi_server.mido, "backend", backend)
    return FAKE_RTMIDI


def make_server(**kwargs) -> tuple[MidiServer, Controller]:
    data = default_config_data()
    data["midi"]["mode"] = "continuous"
    controller = Controller(FakeEngine())
    mapper = MidiMapper(controller, midi_settings(data, 1))
    return MidiServer(mapper, **kwargs), controller


def test_rtmidi_input_is_opened_and_polled_without_a_callback(fake_rtmidi):
    server, controller = make_server(port="keystation", input_names=lambda: list(FakeMidiIn.ports))
    server._open()
    port = server._port
    assert isinstance(port, RtMidiInput) and server._port_name == "Keystation 49:0"
    (midi_in,) = FakeMidiIn.made
    assert midi_in.rtapi == FAKE_RTMIDI.API_UNIX_JACK  # the API MIDO_BACKEND names
    assert midi_in.client_name is None
    assert midi_in.calls == [("open_port", 1), ("ignore_types", False, False, True)]
    assert "RtMidi/jack" in server.describe()
    # messages wait in rtmidi's queue until the input thread polls them
    midi_in.queue += [([0xB0, 11, 127], 0.0), ([0xB0, 74, 127], 0.001)]
    assert list(port.iter_pending_bytes()) == [[0xB0, 11, 127], [0xB0, 74, 127]]
    assert list(port.iter_pending_bytes()) == []
    midi_in.queue.append(([0xB0, 11, 0], 0.0))
    for data in port.iter_pending_bytes():
        server._feed_bytes(data)
    assert controller.get("intensity") == 0.0 and server.received == 1
    # the disconnect watcher lists through the open client, no new backend client
    assert server._list_names() == FakeMidiIn.ports and len(FakeMidiIn.made) == 1
    server._close_port()
    assert midi_in.calls[-2:] == [("close_port",), ("delete",)]
    assert not any(call[0] == "set_callback" for call in midi_in.calls)  # no Python in the backend's thread


def test_rtmidi_virtual_input_is_named_vibsynth(fake_rtmidi):
    server, _ = make_server(virtual=True)
    server._open()
    (midi_in,) = FakeMidiIn.made
    assert midi_in.client_name == "vibsynth"
    assert midi_in.calls[0] == ("open_virtual_port", "vibsynth")


def test_rtmidi_unknown_port_is_an_error_and_frees_the_client(fake_rtmidi):
    with pytest.raises(OSError, match="unknown port 'Gone:0'"):
        RtMidiInput(FAKE_RTMIDI, "Gone:0", virtual=False, api=None)
    assert FakeMidiIn.made[-1].calls == [("delete",)]
    with pytest.raises(OSError, match="unknown MIDI API 'NOPE'"):
        RtMidiInput(FAKE_RTMIDI, "Midi Through:0", virtual=False, api="NOPE")


def test_the_read_loop_polls_rtmidi_bytes(fake_rtmidi):
    server, controller = make_server(port=0, input_names=lambda: list(FakeMidiIn.ports), reconnect_interval_s=60)
    server.start()
    try:
        FakeMidiIn.made[0].queue.append(([0xB0, 11, 127], 0.0))
        end = time.monotonic() + 20.0  # generous: waits for the input thread, asserts no duration
        while server.received == 0 and time.monotonic() < end:
            time.sleep(0.001)
        assert server.received == 1
    finally:
        server.stop()
    assert controller.get("intensity") == 1.0


def test_rtmidi_only_with_mido_rtmidi_backend_and_a_supported_version(monkeypatch):
    rtmidi = pytest.importorskip("rtmidi", reason="python-rtmidi is not installed")
    import importlib.metadata

    monkeypatch.setattr(midi_server.mido, "backend", types.SimpleNamespace(name="mido.backends.rtmidi", api=None))
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "1.5.8")
    assert rtmidi_module() is rtmidi
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "1.3.0")
    assert rtmidi_module() is None  # too old: mido's public API instead
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "2.0.0rc1")
    assert rtmidi_module() is rtmidi
    monkeypatch.setattr(midi_server.mido, "backend", types.SimpleNamespace(name="mido.backends.portmidi", api=None))
    assert rtmidi_module() is None  # another backend: mido's ports


def test_other_backends_are_opened_and_polled_through_mido(monkeypatch):
    opened = []

    class Port(mido.ports.BaseInput):
        def _open(self, **kwargs):
            opened.append((self.name, kwargs))
            self.pending = [mido.Message("control_change", control=11, value=127)]

        def _receive(self, block=True):
            return self.pending.pop(0) if self.pending else None

    monkeypatch.setattr(midi_server, "rtmidi_module", lambda: None)
    monkeypatch.setattr(midi_server.mido, "open_input", lambda name, **kw: Port(name, **kw))
    server, controller = make_server(port="keys", input_names=lambda: ["Keys"])
    server._open()
    assert opened == [("Keys", {})] and not isinstance(server._port, RtMidiInput)
    for msg in server._port.iter_pending():
        server._feed(msg)
    assert controller.get("intensity") == 1.0
    assert server._list_names() == ["Keys"]


@pytest.mark.parametrize(
    "platform, backend, words",
    [
        ("linux", "", ["ALSA sequencer", "MIDO_BACKEND=mido.backends.rtmidi/UNIX_JACK", "a2jmidid"]),
        ("linux", "mido.backends.rtmidi/UNIX_JACK", ["start jackd first"]),
        ("darwin", "", ["IAC Driver", "--midi-virtual"]),
        ("win32", "", ["loopMIDI"]),
    ],
)
def test_port_help_names_the_way_to_ports_on_each_platform(platform, backend, words):
    from vibsynth.control.midi.adapter import port_help

    text = port_help(platform, backend)
    assert all(w in text for w in words) and "docs/midi.md" in text and "\n" not in text


def test_a_missing_backend_warning_says_how_to_get_ports(monkeypatch, caplog):
    import argparse
    import logging

    import mido

    from tests.control.osc.fakes import make_controller
    from vibsynth.control.midi import adapter
    from vibsynth.settings.config import default_config_data

    def broken():
        raise OSError("ALSA lib seq_hw.c:466:(snd_seq_hw_open) open /dev/snd/seq failed: No such file or directory")

    monkeypatch.setattr(mido, "get_input_names", broken)
    monkeypatch.setattr(adapter, "port_help", lambda: "HOW-TO-GET-PORTS")
    args = argparse.Namespace(midi=None, midi_virtual=True, no_midi=False, learn=None, config=None)
    with caplog.at_level(logging.WARNING):
        server = adapter.create(settings_of(default_config_data()), args, make_controller(1), None)
    assert server is None
    (line,) = [r.getMessage() for r in caplog.records if "running without MIDI" in r.getMessage()]
    assert "/dev/snd/seq" in line and line.endswith("HOW-TO-GET-PORTS")


def test_midi_messages_reach_the_tap_with_channels_from_one():
    import mido

    from vibsynth.control.tap import InputTap

    tap = InputTap()
    cursor = tap.attach()
    server, _ = make_server(virtual=True, tap=tap)
    server._feed(mido.Message("control_change", channel=0, control=74, value=90))
    server._feed_bytes([0x91, 60, 100])
    events, _, _ = tap.read(cursor)
    assert [(e.source, e.text) for e in events] == [
        ("midi", f"control_change channel=1 control=74 value=90 time=0  (port {VIRTUAL_PORT_NAME})"),
        ("midi", f"note_on channel=2 note=60 velocity=100 time=0  (port {VIRTUAL_PORT_NAME})"),
    ]
