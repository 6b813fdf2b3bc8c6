"""Null and WAV outputs, device resolution, and the serve fallback logic (no sound card needed)."""

from __future__ import annotations

import logging
import threading
import time
import types

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.app.service import open_output
from vibsynth.engine import outputs
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import NullOutput, SoundDeviceOutput, WavOutput, resolve_device
from vibsynth.errors import DeviceError, ParameterError
from vibsynth.settings.config import load_config


def test_null_output_is_paced_by_the_clock(small_bank):
    e = Engine(small_bank, initial_intensity=0.5, max_block=64)
    out = NullOutput(e, block_size=64)
    out.start()
    assert out.is_running()
    time.sleep(0.3)
    out.stop()
    assert not out.is_running()
    seconds = e.frame_position / e.fs
    assert 0.15 < seconds < 0.6  # real time, not as fast as possible


def test_wav_output_renders_the_duration(tmp_path, small_bank):
    e = Engine(small_bank, initial_intensity=0.5, channels=2)
    path = tmp_path / "out.wav"
    out = WavOutput(e, path, seconds=0.5, block_size=256)
    out.start()
    assert out.written.wait(10)
    out.stop()
    fs, data = wavfile.read(path)
    assert fs == int(small_bank.fs) and data.shape == (8000, 2) and data.dtype == np.float32
    ref = Engine(small_bank, initial_intensity=0.5, channels=2).render(8000)
    np.testing.assert_array_equal(data, ref)
    with pytest.raises(ParameterError):
        WavOutput(e, path, seconds=0)


def fake_sd(devices, apis=None, default_out=-1):
    apis = apis or [{"name": "ALSA", "default_output_device": default_out}]
    sd = types.SimpleNamespace()
    sd.query_devices = lambda i=None: devices if i is None else devices[i]
    sd.query_hostapis = lambda i=None: apis if i is None else apis[i]
    sd.default = types.SimpleNamespace(device=(-1, default_out))
    return sd


DEVICES = [
    {"name": "mic", "hostapi": 0, "max_output_channels": 0},
    {"name": "Speakers (USB)", "hostapi": 0, "max_output_channels": 2},
    {"name": "USB Haptic 8ch", "hostapi": 1, "max_output_channels": 8},
]
APIS = [{"name": "ALSA", "default_output_device": 1}, {"name": "JACK Audio Connection Kit", "default_output_device": 2}]


def test_resolve_device_by_index_name_and_host_api():
    sd = fake_sd(DEVICES, APIS, default_out=1)
    assert resolve_device(sd, None) == 1
    assert resolve_device(sd, 2) == 2
    assert resolve_device(sd, "haptic") == 2
    assert resolve_device(sd, None, "jack") == 2
    with pytest.raises(DeviceError, match="ambiguous"):
        resolve_device(sd, "usb")
    with pytest.raises(DeviceError, match="not an output"):
        resolve_device(sd, 0)
    with pytest.raises(DeviceError, match="no output device matches"):
        resolve_device(sd, "nope")
    with pytest.raises(DeviceError, match="no host API"):
        resolve_device(sd, None, "wasapi")
    with pytest.raises(DeviceError, match="no audio output device"):
        resolve_device(fake_sd(DEVICES[:1]), None)


def test_channel_map_validation(small_bank):
    e = Engine(small_bank, channels=2)
    with pytest.raises(ParameterError):
        SoundDeviceOutput(e, channel_map=[1])
    with pytest.raises(ParameterError):
        SoundDeviceOutput(e, channel_map=[2, 2])
    out = SoundDeviceOutput(e, channel_map=[3, 1])
    assert out.device_channels == 3


PA_OUTPUT_UNDERFLOW = 0x4


def test_compiled_callback_maps_channels_and_counts_underflows(small_bank):
    """The real C callback PortAudio calls: channel map, untouched columns zeroed, flags counted."""
    e = Engine(small_bank, channels=2, initial_intensity=0.5)
    out = SoundDeviceOutput(e, channel_map=[3, 1], block_size=64)
    e.set_output_map(out.device_channels, out.channel_map)
    buf = np.full((64, 3), 7.0, dtype=np.float32)
    assert e._core.run_callback(buf, PA_OUTPUT_UNDERFLOW) == 0  # paContinue
    ref = Engine(small_bank, channels=2, initial_intensity=0.5).render(64)
    np.testing.assert_array_equal(buf[:, 2], ref[:, 0])
    np.testing.assert_array_equal(buf[:, 0], ref[:, 1])
    assert not buf[:, 1].any()
    assert out.stats.underflows == 1 and e.stats.underflows == 1 and out.stats.callbacks == 1
    e._core.run_callback(buf, 0)
    assert out.stats.underflows == 1 and out.stats.callbacks == 2


@pytest.fixture
def no_portaudio(monkeypatch):
    def fail():
        raise DeviceError("PortAudio is not available (test)")

    monkeypatch.setattr(outputs, "import_sounddevice", fail)


def test_auto_falls_back_to_null_with_a_warning(small_bank, no_portaudio, caplog):
    config = load_config(overrides={"audio": {"backend": "auto"}})
    e = Engine(small_bank)
    with caplog.at_level(logging.WARNING):
        out = open_output(config, e, explicit_device=False)
    assert isinstance(out, NullOutput)
    assert "falling back to the null output" in caplog.text


def test_explicit_device_or_backend_is_an_error(small_bank, no_portaudio):
    e = Engine(small_bank)
    with pytest.raises(DeviceError):
        open_output(load_config(overrides={"audio": {"backend": "auto"}}), e, explicit_device=True)
    with pytest.raises(DeviceError):
        open_output(load_config(overrides={"audio": {"backend": "sounddevice"}}), e, explicit_device=False)


def test_serve_cli_exit_codes(no_portaudio, tmp_path, capsys):
    from vibsynth.cli import main

    config = tmp_path / "config.yaml"
    config.write_text(f"bank:\n  cache_dir: {tmp_path / 'cache'}\n  loop_seconds: 0.5\n  levels: 5\n")
    flags = ["--no-osc"] if _has_osc() else []
    assert main(["serve", "--config", str(config), "--device", "x", "--seconds", "0.1", *flags]) == 2
    assert "PortAudio" in capsys.readouterr().err
    assert main(["serve", "--config", str(config), "--seconds", "0.2", "--intensity", "0.5", *flags]) == 0
    assert "make it vibrate" in capsys.readouterr().out
    assert main(["serve", "--config", str(config), "--seconds", "0.1", "--balance", "9", *flags]) == 2
    assert "balance" in capsys.readouterr().err


def _has_osc() -> bool:
    try:
        import vibsynth.control.osc.server  # noqa: F401
    except ImportError:
        return False
    return True


class _FakeStream:
    """A PortAudio stream stand-in: while active, a thread calls the engine's callback every 5 ms."""

    opened: list[_FakeStream] = []
    engine: Engine | None = None

    def __init__(self, kind="output", *, callback, finished_callback, userdata=None, **kwargs):
        self.callback, self.userdata, self.finished_callback, self.kwargs = (
            callback,
            userdata,
            finished_callback,
            kwargs,
        )
        self.active = False
        self.closed = False
        _FakeStream.opened.append(self)

    def _run(self):
        buf = np.zeros((64, 1), dtype=np.float32)
        while self.active:
            _FakeStream.engine._core.run_callback(buf, 0)
            time.sleep(0.005)

    def start(self):
        self.active = True
        threading.Thread(target=self._run, daemon=True).start()

    def stop(self):
        self.active = False

    def abort(self):
        self.active = False

    def close(self):
        self.closed = True

    def device_error(self):
        """What PortAudio does when the device vanishes: the stream ends and says so."""
        self.active = False
        self.finished_callback()


def _fake_portaudio(sd):
    """The PortAudio calls of a re-scan (Pa_Terminate + Pa_Initialize) on a fake sounddevice."""
    sd._lib = types.SimpleNamespace(Pa_Initialize=lambda: 0, Pa_Terminate=lambda: 0)
    sd._initialized = 1
    sd._check = lambda code, msg="": code

    def terminate():
        sd._initialized -= 1

    sd._terminate = terminate


def test_supervisor_restarts_the_stream_after_a_device_error(small_bank, monkeypatch):
    _FakeStream.opened = []
    sd = fake_sd(DEVICES, APIS, default_out=1)
    sd._StreamBase = _FakeStream
    sd._ffi = types.SimpleNamespace(cast=lambda ctype, value: value)
    _fake_portaudio(sd)
    monkeypatch.setattr(outputs, "import_sounddevice", lambda: sd)
    out = SoundDeviceOutput(Engine(small_bank, channels=1), block_size=64)
    _FakeStream.engine = out.engine
    out.start()
    try:
        first = _FakeStream.opened[0]
        deadline = time.monotonic() + 5.0
        while out.state != "streaming" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert out.is_running() and out.state == "streaming"
        first.device_error()
        while out.state != "device lost" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert out.state_reason == "stream stopped"
        while out.state != "streaming" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert out.state == "streaming" and out.stats.restarts == 1
        assert out.supervisor.recovered_after_s < 1.0  # first retry after 0.25 s
        assert first.closed and len(_FakeStream.opened) == 2
        assert out.is_running() and _FakeStream.opened[1].active
        # the new stream runs the same engine's compiled callback
        assert (_FakeStream.opened[1].callback, _FakeStream.opened[1].userdata) == out.engine.callback_addresses()
    finally:
        out.stop()
    assert not _FakeStream.opened[1].active and _FakeStream.opened[1].closed
    assert out.state == "stopped"
