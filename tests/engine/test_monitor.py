"""``--follow monitor``: the paths tried, the message when none exists, and the JACK patch-bay logic on a fake graph."""

from __future__ import annotations

import os
import sys
from types import SimpleNamespace

import pytest

from vibsynth.engine import monitor, monitor_patchbay
from vibsynth.engine.inputs import SoundDeviceInput
from vibsynth.engine.monitor import MonitorInput, is_monitor_spec
from vibsynth.engine.monitor_patchbay import JackPatcher, import_jack
from vibsynth.errors import DeviceError


class FakeSoundDevice:
    def __init__(self, apis, devices):
        self._apis, self._devices = apis, devices

    def query_hostapis(self):
        return self._apis

    def query_devices(self):
        return self._devices


def test_monitor_is_the_word_and_an_unopened_monitor_has_no_ring():
    assert is_monitor_spec("monitor") and is_monitor_spec(" Monitor ") and not is_monitor_spec("monitor:1")
    source = MonitorInput(fs=48000.0, host_api="JACK", block_size=128)
    assert source.fs == 48000.0 and source.device_input is SoundDeviceInput  # the default: a real device input
    with pytest.raises(DeviceError, match="not open yet"):
        source.ring  # noqa: B018


def test_no_monitor_anywhere_is_one_message_naming_what_was_tried(monkeypatch):
    sd = FakeSoundDevice([{"name": "ALSA"}], [{"name": "hw:0,0", "hostapi": 0, "max_input_channels": 2}])
    monkeypatch.setattr(monitor, "import_sounddevice", lambda: sd)
    with pytest.raises(DeviceError) as info:
        MonitorInput(fs=48000.0, device_input=SoundDeviceInput).open()
    message = str(info.value)
    assert message.startswith("no loopback/monitor input on this system; tried JACK: PortAudio has no JACK host API")
    assert "PulseAudio/PipeWire: PortAudio lists no 'pulse' or 'pipewire' input device" in message
    assert "WASAPI loopback: PortAudio lists no WASAPI [Loopback] input device" in message


class FakeDeviceInput:
    """What MonitorInput opens: records its spec and host API; ``fail`` makes open() refuse."""

    made: list[tuple[str, object]] = []
    fail = ""

    def __init__(self, spec, *, fs, host_api, block_size):
        self.spec, self.host_api = spec, host_api
        FakeDeviceInput.made.append((spec, host_api))

    def open(self):
        if FakeDeviceInput.fail:
            raise DeviceError(FakeDeviceInput.fail)

    def status(self):
        return {"device": f"device {self.spec}", "state": "open", "reason": ""}


@pytest.fixture
def fake_devices(monkeypatch):
    monkeypatch.setenv("PULSE_SOURCE", "")  # recorded, so the value the monitor path sets is undone after the test
    monkeypatch.delenv("PULSE_SOURCE")
    FakeDeviceInput.made, FakeDeviceInput.fail = [], ""

    def use(apis, devices):
        monkeypatch.setattr(monitor, "import_sounddevice", lambda: FakeSoundDevice(apis, devices))

    return use


def test_on_pulseaudio_or_pipewire_the_monitor_is_the_default_outputs_monitor(fake_devices, monkeypatch):
    fake_devices(
        [{"name": "ALSA"}],
        [
            {"name": "HDA Intel: ALC (hw:0,0)", "hostapi": 0, "max_input_channels": 2},
            {"name": "pipewire", "hostapi": 0, "max_input_channels": 64},
            {"name": "pulse", "hostapi": 0, "max_input_channels": 32},
        ],
    )
    source = MonitorInput(fs=48000.0, device_input=FakeDeviceInput)
    source.open()
    assert FakeDeviceInput.made == [("1:1,2", None)] and source.path == "PulseAudio/PipeWire"
    assert os.environ["PULSE_SOURCE"] == "@DEFAULT_MONITOR@"
    assert source.status()["device"] == "monitor (PulseAudio/PipeWire: device 1:1,2)"


def test_on_windows_the_first_wasapi_loopback_device_is_taken(fake_devices):
    fake_devices(
        [{"name": "MME"}, {"name": "Windows WASAPI"}],
        [
            {"name": "Speakers (Realtek) [Loopback]", "hostapi": 0, "max_input_channels": 2},  # MME: not it
            {"name": "Microphone (Realtek)", "hostapi": 1, "max_input_channels": 2},
            {"name": "Speakers (Realtek) [Loopback]", "hostapi": 1, "max_input_channels": 2},
        ],
    )
    source = MonitorInput(fs=48000.0, device_input=FakeDeviceInput)
    source.open()
    assert FakeDeviceInput.made == [("2:1,2", "WASAPI")] and source.path == "WASAPI loopback"


def test_a_path_whose_device_refuses_to_open_is_named_with_its_reason(fake_devices):
    fake_devices([{"name": "ALSA"}], [{"name": "pulse", "hostapi": 0, "max_input_channels": 32}])
    FakeDeviceInput.fail = "cannot open input 'pulse' at 48000 Hz: Device unavailable"
    with pytest.raises(DeviceError, match="PulseAudio/PipeWire: cannot open input 'pulse' at 48000 Hz"):
        MonitorInput(fs=48000.0, device_input=FakeDeviceInput).open()


def test_without_the_jack_package_the_message_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "jack", None)
    with pytest.raises(DeviceError, match=r"needs the JACK-Client package .*pip install 'vibsynth\[monitor\]'"):
        import_jack()


class FakePort(SimpleNamespace):
    pass


class FakeClient:
    """A JACK graph: port names -> kind, and a set of (source, destination) connections."""

    name = "vibsynth-monitor-1"

    def __init__(self, graph):
        self.graph = graph

    def get_ports(self, is_audio=True, is_input=False, is_physical=False):
        names = self.graph.inputs if is_input else self.graph.outputs
        return [FakePort(name=n) for n in names if not is_physical or n.startswith("system:")]

    def get_port_by_name(self, name):
        return FakePort(name=name)

    def get_all_connections(self, port):
        return [FakePort(name=a if b == port.name else b) for a, b in self.graph.links if port.name in (a, b)]

    def connect(self, a, b):
        self.graph.links.add((a, b))

    def disconnect(self, a, b):
        self.graph.links.discard((a, b))

    def close(self):
        pass


def test_the_patcher_connects_what_feeds_the_playback_ports_to_our_new_ports_and_not_our_outputs(monkeypatch):
    graph = SimpleNamespace(
        inputs=["system:playback_1", "system:playback_2", "PortAudio:in_0", "PortAudio:in_1"],  # another app's
        outputs=["system:capture_1", "PortAudio-01:out_0", "game:L", "game:R"],
        links={
            ("PortAudio-01:out_0", "system:playback_1"),
            ("game:L", "system:playback_1"),
            ("game:R", "system:playback_2"),
        },
    )
    patcher = JackPatcher(FakeClient(graph), 2)
    patcher.snapshot()  # before our stream opens: PortAudio:in_* belong to someone else
    graph.inputs += ["PortAudio-01:in_0", "PortAudio-01:in_1"]
    graph.links.add(("system:capture_1", "PortAudio-01:in_0"))  # PortAudio's own auto-connection
    patcher.poll()
    assert patcher.own == ["PortAudio-01:in_0", "PortAudio-01:in_1"]
    assert ("game:L", "PortAudio-01:in_0") in graph.links and ("game:R", "PortAudio-01:in_1") in graph.links
    assert ("PortAudio-01:out_0", "PortAudio-01:in_0") not in graph.links  # our own output is not followed
    assert ("system:capture_1", "PortAudio-01:in_0") not in graph.links
    assert not any(b.startswith("PortAudio:") for _, b in graph.links)  # the other app's ports untouched
    assert patcher.sources == ["game:L", "game:R"] and patcher.connections == 2
    # a new program starts playing: followed at the next poll; one that stops is let go
    graph.outputs.append("video:out")
    graph.links.add(("video:out", "system:playback_2"))
    graph.links.discard(("game:L", "system:playback_1"))
    patcher.poll()
    assert ("video:out", "PortAudio-01:in_1") in graph.links and ("game:L", "PortAudio-01:in_0") not in graph.links
    assert patcher.sources == ["game:R", "video:out"]


def test_a_restarted_server_patches_the_ports_of_the_same_name_again():
    graph = SimpleNamespace(
        inputs=["system:playback_1", "PortAudio:in_0", "PortAudio:in_1"],
        outputs=["game:L"],
        links={("game:L", "system:playback_1")},
    )
    patcher = JackPatcher(FakeClient(graph), 2, own=["PortAudio:in_0", "PortAudio:in_1"])
    patcher.snapshot()  # the child starts after serve's input reopened: its ports are there already
    patcher.poll()
    assert patcher.own == ["PortAudio:in_0", "PortAudio:in_1"] and ("game:L", "PortAudio:in_0") in graph.links


def test_the_patch_bay_says_why_it_cannot_run_and_exits(monkeypatch, capsys):
    def no_jack():
        raise DeviceError("the JACK monitor input needs the JACK-Client package (gone)")

    monkeypatch.setattr(monitor_patchbay, "import_jack", no_jack)
    assert monitor_patchbay.main(["--parent", "1"]) == 3
    assert '{"error": "JACK: the JACK monitor input needs the JACK-Client package (gone)"}' in capsys.readouterr().out
