"""Null and WAV outputs, device resolution, and the serve fallback logic (no sound card needed).

Time is driven explicitly: the null output and the supervisor run on fake clocks and are
stepped by the tests; fake PortAudio streams are "played" by calling the engine's compiled
callback (``run_callback``). Real threads are waited for on conditions with generous deadlines.
"""

from __future__ import annotations

import logging
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.app.service import open_output
from vibsynth.engine import outputs
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import NullOutput, SoundDeviceOutput, WavOutput, resolve_device
from vibsynth.engine.supervisor import Backoff
from vibsynth.errors import DeviceError, ParameterError
from vibsynth.settings.config import load_config

from .waiting import returns, wait_until


class Clock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_null_output_is_paced_by_the_clock(small_bank):
    e = Engine(small_bank, initial_intensity=0.5, max_block=64)
    clock = Clock()
    out = NullOutput(e, block_size=64, clock=clock)
    period = 64 / e.fs
    # the clock does not move: each block is due one period after the previous one
    delays = [out.step() for _ in range(4)]
    np.testing.assert_allclose(delays, period * np.arange(1, 5))
    # waiting what it asks keeps it exactly on time: one block per period, no underflow
    for _ in range(100):
        clock.t += out.step()
    assert e.frame_position == 104 * 64 and out.stats.callbacks == 104 and out.stats.underflows == 0
    assert out.step() == pytest.approx(period)  # back on schedule: the next block is one period away
    # what it renders is the engine's output, block after block
    ref = Engine(small_bank, initial_intensity=0.5, max_block=64)
    ref.render(104 * 64)
    np.testing.assert_array_equal(out.last_block, ref.render(64))


def test_null_output_counts_a_late_block_and_resyncs(small_bank):
    e = Engine(small_bank, max_block=64)
    clock = Clock()
    out = NullOutput(e, block_size=64, max_lag_s=0.05, clock=clock)
    period = 64 / e.fs
    clock.t += out.step()
    clock.t += 0.04  # late, but within max_lag_s
    assert out.step() < 0 and out.stats.underflows == 0
    clock.t += 0.2  # the machine stalled
    assert out.step() < -0.05
    assert out.stats.underflows == 1 and e.stats.underflows == 1
    assert out.step() == pytest.approx(period)  # resynced to now: no burst of catch-up blocks


def test_null_output_thread_renders_until_stopped(small_bank):
    e = Engine(small_bank, max_block=64)
    out = NullOutput(e, block_size=64)
    out.start()
    try:
        assert out.is_running()
        wait_until(lambda: out.stats.callbacks >= 3, "the null output renders blocks")
    finally:
        out.stop()
    assert not out.is_running()
    frames = e.frame_position
    assert frames == out.stats.callbacks * 64  # whole blocks, and nothing after stop


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


def test_wav_output_streams_with_flat_memory(tmp_path, small_bank):
    """240 s of 2 channels at 16 kHz (31 MB of samples): Python allocates one block and the file buffer."""
    import tracemalloc

    e = Engine(small_bank, initial_intensity=0.5, channels=2)
    path = tmp_path / "long.wav"
    tracemalloc.start()
    try:
        out = WavOutput(e, path, seconds=240.0, block_size=1024)
        out.start()
        assert out.written.wait(60)
        out.stop()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    frames = 240 * int(small_bank.fs)
    assert peak < 4 << 20, peak  # the file's 1 MiB write buffer and a block; the whole output is 31 MB
    fs, data = wavfile.read(path, mmap=True)
    assert fs == int(small_bank.fs) and data.shape == (frames, 2)
    ref = Engine(small_bank, initial_intensity=0.5, channels=2).render(frames)
    np.testing.assert_array_equal(data, ref)


def test_wav_output_refuses_an_unwritable_file_before_rendering(tmp_path, small_bank):
    from tests.formats.readonly import read_only_folder

    e = Engine(small_bank, channels=1)
    with pytest.raises(FileNotFoundError) as info:
        WavOutput(e, tmp_path / "missing" / "x.wav", seconds=0.1)
    assert info.value.filename == str(tmp_path / "missing")
    with pytest.raises(IsADirectoryError):
        WavOutput(e, tmp_path, seconds=0.1)
    with read_only_folder(tmp_path / "ro") as ro, pytest.raises(OSError) as info:
        WavOutput(e, ro / "x.wav", seconds=0.1)
    assert str(ro) in str(info.value)
    assert e.stats.callbacks == 0 and not list((tmp_path / "ro").iterdir())


def test_wav_output_stopped_before_start_writes_nothing(tmp_path, small_bank):
    out = WavOutput(Engine(small_bank, channels=1), tmp_path / "x.wav", seconds=0.1)
    out.stop()
    assert out.written.is_set() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("anonymous", [True, False])
def test_wav_output_stopped_early_keeps_what_was_rendered(tmp_path, small_bank, anonymous):
    e = Engine(small_bank, initial_intensity=0.5, channels=1)
    out = WavOutput(e, tmp_path / "x.wav", seconds=0.5, block_size=256)
    if not anonymous:  # the named temporary file path (systems without O_TMPFILE)
        from vibsynth.formats.wav_stream import WavStreamWriter

        out._writer.abort()
        out._writer = WavStreamWriter(tmp_path / "x.wav", e.fs, 1, frames=out.frames, anonymous=False)
    out._stop.set()  # stop requested before the first block: an empty but valid file
    out.start()
    out.stop()
    fs, data = wavfile.read(tmp_path / "x.wav")
    assert data.shape == (0,) and [p.name for p in tmp_path.iterdir()] == ["x.wav"]


def _failing_wav_output(tmp_path, small_bank, how: str) -> tuple[WavOutput, Path]:
    folder = tmp_path / "out"
    folder.mkdir()
    target = folder / "x.wav"
    out = WavOutput(Engine(small_bank, initial_intensity=0.5, channels=1), target, seconds=0.5, block_size=256)
    if how == "folder removed":  # the anonymous temporary file is not in the folder: it can go
        folder.rmdir()
    else:  # a folder where the file should go: the final rename fails
        (target / "keep").mkdir(parents=True)
    return out, target


@pytest.mark.parametrize("how", ["folder removed", "target became a folder"])
def test_wav_output_write_failure_is_kept_and_raised_by_stop(tmp_path, small_bank, how):
    out, target = _failing_wav_output(tmp_path, small_bank, how)
    out.start()
    assert out.written.wait(10)
    assert isinstance(out.error, OSError)
    with pytest.raises(OSError) as info:
        out.stop()
    assert info.value.filename == str(target) or info.value.filename == str(target.parent)
    out.stop()  # raised once
    if how == "folder removed":
        assert not target.parent.exists()
    else:
        assert [p.name for p in target.iterdir()] == ["keep"]
        assert [p.name for p in target.parent.iterdir()] == ["x.wav"]  # no temporary file left


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
        out = open_output(config.settings.audio, e, explicit_device=False)
    assert isinstance(out, NullOutput)
    assert "falling back to the null output" in caplog.text


def test_explicit_device_or_backend_is_an_error(small_bank, no_portaudio):
    e = Engine(small_bank)
    with pytest.raises(DeviceError):
        open_output(load_config(overrides={"audio": {"backend": "auto"}}).settings.audio, e, explicit_device=True)
    with pytest.raises(DeviceError):
        open_output(
            load_config(overrides={"audio": {"backend": "sounddevice"}}).settings.audio, e, explicit_device=False
        )


def test_serve_cli_exit_codes(no_portaudio, tmp_path, capsys):
    from vibsynth.cli import main

    config = tmp_path / "config.yaml"
    config.write_text(f"bank:\n  cache_dir: {tmp_path / 'cache'}\n  loop_seconds: 0.5\n  levels: 5\n")
    flags = ["--no-osc"] if _has_osc() else []
    assert main(["serve", "--config", str(config), "--device", "x", "--seconds", "0.1", *flags]) == 1  # a device
    assert "PortAudio" in capsys.readouterr().err
    assert main(["serve", "--config", str(config), "--seconds", "0.2", "--intensity", "0.5", *flags]) == 0
    assert "make it vibrate" in capsys.readouterr().out
    assert main(["serve", "--config", str(config), "--seconds", "0.1", "--balance", "9", *flags]) == 2
    assert "balance" in capsys.readouterr().err


def _serve_wav(tmp_path, target, *extra: str) -> list[str]:
    config = tmp_path / "config.yaml"
    config.write_text(
        f"audio:\n  rate: 8000\nbank:\n  cache_dir: {tmp_path / 'cache'}\n  loop_seconds: 0.5\n  levels: 5\n"
    )
    flags = ["--no-osc"] if _has_osc() else []
    return ["serve", "--config", str(config), "--output", "wav", "-o", str(target), *flags, *extra]


def test_serve_wav_output_refuses_an_unwritable_file_at_start(no_portaudio, tmp_path, capsys):
    from tests.formats.readonly import read_only_folder
    from vibsynth.cli import main

    missing = tmp_path / "missing"
    assert main(_serve_wav(tmp_path, missing / "x.wav", "--seconds", "0.2")) == 1
    out, err = capsys.readouterr()
    assert err == f"vibsynth: error: {missing}: folder does not exist\n" and "serving" not in out
    assert not (tmp_path / "cache").exists()  # refused before the bank was built
    assert main(_serve_wav(tmp_path, tmp_path, "--seconds", "0.2")) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"vibsynth: error: {tmp_path}: ") and "is a folder" in err and err.count("\n") == 1
    with read_only_folder(tmp_path / "ro") as ro:
        assert main(_serve_wav(tmp_path, ro / "x.wav", "--seconds", "0.2")) == 1
        err = capsys.readouterr().err
        assert err.startswith(f"vibsynth: error: {ro}: ") and err.count("\n") == 1, err
        assert not list(ro.iterdir())
    assert main(_serve_wav(tmp_path, tmp_path / "x.wav")) == 2  # no --seconds: a bad argument
    assert capsys.readouterr().err == "vibsynth: error: the wav output needs a duration: --seconds N\n"
    assert not (tmp_path / "cache").exists() and not (tmp_path / "x.wav").exists()


@pytest.mark.parametrize("how", ["folder removed", "target became a folder"])
def test_serve_wav_output_write_failure_exits_1(no_portaudio, tmp_path, capsys, monkeypatch, how):
    from vibsynth.cli import main

    folder = tmp_path / "out"
    folder.mkdir()
    target = folder / "x.wav"
    start = WavOutput.start

    def start_then_break(self):  # the file system changes under the running service
        if how == "folder removed":
            folder.rmdir()
        else:
            (target / "keep").mkdir(parents=True)
        start(self)

    monkeypatch.setattr(WavOutput, "start", start_then_break)
    assert main(_serve_wav(tmp_path, target, "--seconds", "5", "--intensity", "0.5")) == 1
    out, err = capsys.readouterr()
    assert "serving 1 channel(s) on wav file" in out
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("vibsynth: error: ") and str(folder) in lines[0], err
    if how == "target became a folder":
        assert [p.name for p in folder.iterdir()] == ["x.wav"] and [p.name for p in target.iterdir()] == ["keep"]


def test_serve_wav_output_writes_the_file(no_portaudio, tmp_path, capsys):
    from vibsynth.cli import main

    assert main(_serve_wav(tmp_path, tmp_path / "x.wav", "--seconds", "0.5", "--intensity", "0.5")) == 0
    fs, data = wavfile.read(tmp_path / "x.wav")
    assert fs == 8000 and data.shape == (4000,) and np.abs(data).max() > 0


def _has_osc() -> bool:
    try:
        import vibsynth.control.osc.server  # noqa: F401
    except ImportError:
        return False
    return True


class _FakeStream:
    """A PortAudio stream stand-in, played by the test: :meth:`play` calls the engine's compiled callback."""

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

    def play(self, blocks: int = 3) -> None:
        """What PortAudio does while the stream runs: a few callbacks (the heartbeat moves)."""
        buf = np.zeros((64, 1), dtype=np.float32)
        for _ in range(blocks):
            if self.active:
                _FakeStream.engine._core.run_callback(buf, 0)

    def start(self):
        self.active = True

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


def _fake_sd_output(bank, monkeypatch, **kwargs) -> SoundDeviceOutput:
    _FakeStream.opened = []
    sd = fake_sd(DEVICES, APIS, default_out=1)
    sd._StreamBase = _FakeStream
    sd._ffi = types.SimpleNamespace(cast=lambda ctype, value: value)
    _fake_portaudio(sd)
    monkeypatch.setattr(outputs, "import_sounddevice", lambda: sd)
    out = SoundDeviceOutput(Engine(bank, channels=1), block_size=64, **kwargs)
    _FakeStream.engine = out.engine
    return out


def test_supervisor_restarts_the_stream_after_a_device_error(small_bank, monkeypatch):
    clock = Clock(1000.0)
    out = _fake_sd_output(small_bank, monkeypatch, restart=False, clock=clock)
    out.start()
    try:
        first = _FakeStream.opened[0]
        assert out.state == "starting"
        first.play()
        assert out.supervisor.step() == "streaming" and out.is_running()
        first.device_error()
        clock.t += 0.05
        assert out.supervisor.step() == "device lost" and out.state_reason == "stream stopped"
        assert first.closed and not out.is_running()
        clock.t += 0.2
        assert out.supervisor.step() == "device lost" and len(_FakeStream.opened) == 1  # back-off: 0.25 s
        clock.t += 0.05
        assert out.supervisor.step() == "recovering" and len(_FakeStream.opened) == 2
        second = _FakeStream.opened[1]
        assert second.active and out.state_reason == "stream stopped"
        second.play()
        clock.t += 0.05
        assert out.supervisor.step() == "streaming" and out.state_reason == ""
        assert out.supervisor.recovered_after_s == pytest.approx(0.30)  # lost at +0.05, streaming at +0.35
        assert out.stats.restarts == 1 and out.engine.stats.output_errors == 1
        # the new stream runs the same engine's compiled callback
        assert (second.callback, second.userdata) == out.engine.callback_addresses()
    finally:
        out.stop()
    assert not second.active and second.closed
    assert out.state == "stopped"


def test_supervisor_thread_brings_the_stream_back(small_bank, monkeypatch):
    """The real supervisor thread (restart=True); no heartbeat timeout, so only the device error counts."""
    interval = sys.getswitchinterval()
    out = _fake_sd_output(small_bank, monkeypatch, heartbeat_timeout_s=3600.0, backoff=Backoff(0.01, 0.01))
    out.start()
    try:
        first = _FakeStream.opened[0]
        first.play()
        wait_until(lambda: out.state == "streaming", "streaming after the first blocks")
        first.device_error()
        wait_until(lambda: len(_FakeStream.opened) == 2, "the supervisor thread reopens the stream")
        second = _FakeStream.opened[1]
        wait_until(lambda: out.state == "recovering", "recovering until the new stream plays")
        second.play()
        wait_until(lambda: out.state == "streaming", "streaming again")
        assert out.stats.restarts == 1 and first.closed and second.active
    finally:
        returns(out.stop, "stop")
    assert out.state == "stopped" and second.closed
    assert sys.getswitchinterval() == interval  # the output never touches the GIL switch interval


def test_outputs_and_serve_leave_the_switch_interval_alone(small_bank, no_portaudio, tmp_path, capsys):
    """The compiled callback needs no GIL: nothing sets sys.setswitchinterval any more."""
    from vibsynth.cli import main

    interval = sys.getswitchinterval()
    out = NullOutput(Engine(small_bank), block_size=64)
    out.start()
    wait_until(lambda: out.stats.callbacks > 0, "the null output renders")
    out.stop()
    assert sys.getswitchinterval() == interval
    config = tmp_path / "config.yaml"
    config.write_text(f"bank:\n  cache_dir: {tmp_path / 'cache'}\n  loop_seconds: 0.5\n  levels: 5\n")
    flags = ["--no-osc"] if _has_osc() else []
    assert main(["serve", "--config", str(config), "--seconds", "0.05", *flags]) == 0
    assert sys.getswitchinterval() == interval
