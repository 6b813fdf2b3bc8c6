"""Input sources: device specs, the supervised device input beside the output, the paced file input.

The device input runs on the fake PortAudio of ``test_supervisor`` (devices seen at
``Pa_Initialize``, streams that die like JACK's or ALSA's); its blocks are "captured" by calling
the ring's compiled callback. Time is the supervisor's fake clock; the file input's output clock is
a counter the test advances.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
from scipy.io import wavfile
from scipy.signal import resample_poly

from vibsynth.engine import outputs
from vibsynth.engine.engine import Engine
from vibsynth.engine.inputs import FileInput, SoundDeviceInput, level_db, parse_input_spec
from vibsynth.engine.outputs import SoundDeviceOutput
from vibsynth.engine.pa_runtime import shared_runtime
from vibsynth.engine.supervisor import LOST, STREAMING
from vibsynth.errors import DeviceError, InputError, ParameterError

from .test_supervisor import ALSA_API, JACK_API, Clock, World, install_fake_portaudio, pump
from .waiting import returns, wait_until

JACK_SYSTEM = {"name": "system", "hostapi": 1, "max_output_channels": 2, "max_input_channels": 8}
ALSA_MIC = {"name": "USB mic: Audio (hw:2,0)", "hostapi": 0, "max_output_channels": 0, "max_input_channels": 2}
ALSA_OUT = {"name": "USB haptics", "hostapi": 0, "max_output_channels": 2, "max_input_channels": 0}


class InputWorld(World):
    """JACK's system device (8 capture, 2 playback), an ALSA output and an ALSA microphone."""

    def __init__(self) -> None:
        super().__init__()
        self.mic_up = True

    def scan(self):
        apis = [dict(ALSA_API, default_input_device=1), dict(JACK_API, default_input_device=2)]
        devices = [ALSA_OUT] + ([ALSA_MIC] if self.mic_up else [])
        if self.jack_up:
            return apis, devices + [JACK_SYSTEM]
        return apis[:1], devices


@pytest.fixture
def world():
    w = InputWorld()
    yield w
    w.hang.set()


@pytest.fixture
def sd(world, tmp_path, monkeypatch):
    return install_fake_portaudio(world, tmp_path, monkeypatch)


def capture(inp: SoundDeviceInput, blocks: int = 3, frames: int = 64) -> np.ndarray:
    """What PortAudio does while an input runs: call the compiled callback with device frames."""
    rng = np.random.default_rng(inp.ring.callbacks)
    sent = rng.standard_normal((blocks * frames, inp.ring.device_channels)).astype(np.float32)
    for b in range(blocks):
        inp.ring.run_callback(sent[b * frames : (b + 1) * frames])
    return sent


def beat(inp: SoundDeviceInput) -> None:
    """A block from the input's stream if it plays (a reopened stream's first blocks)."""
    if inp._stream is not None and inp._stream.active:
        capture(inp, 1)


def make_input(spec, clock, host_api="JACK") -> SoundDeviceInput:
    return SoundDeviceInput(spec, fs=16000.0, host_api=host_api, block_size=64, restart=False, clock=clock)


# ---------------------------------------------------------------------- specs
@pytest.mark.parametrize(
    ("text", "device", "channels"),
    [
        ("system:1,2", "system", (1, 2)),
        ("system", "system", None),
        ("3", 3, None),
        ("3:4", 3, (4,)),
        ("", None, None),
        (":2", None, (2,)),
        ("USB mic: Audio (hw:2,0):1", "USB mic: Audio (hw:2,0)", (1,)),
    ],
)
def test_device_specs_parse(text, device, channels):
    spec = parse_input_spec(text)
    assert (spec.device, spec.channels, spec.text) == (device, channels, text)


def test_bad_specs_are_one_clear_error():
    with pytest.raises(ParameterError, match="numbered from 1"):
        parse_input_spec("system:0,1")
    with pytest.raises(ParameterError, match="channel listed twice"):
        parse_input_spec("system:1,1")
    with pytest.raises(ParameterError, match="at most 64 channels"):
        parse_input_spec("system:" + ",".join(str(c) for c in range(1, 66)))


def test_channels_the_device_lacks_name_the_device_and_its_channels(sd, world):
    inp = make_input("system:2,9,12", Clock())
    with pytest.raises(
        DeviceError, match=r"input device 'system' has 8 inputs \(channels 1\.\.8\); 9, 12 do not exist"
    ):
        inp.open()
    with pytest.raises(DeviceError, match="no input device matches 'nothing'"):
        make_input("nothing:1", Clock()).open()
    with pytest.raises(DeviceError, match="is not an input device"):
        make_input("0", Clock(), host_api=None).open()  # the ALSA output has no inputs


def test_a_name_ending_in_numbers_is_found_whole(sd, world):
    inp = make_input("USB mic: Audio (hw:2,0)", Clock(), host_api="ALSA")
    inp.open()
    assert inp.channels == (1, 2)  # a name, not "(hw" with channels 2,0
    assert sd.streams[-1].kwargs["device"] == 1 and sd.streams[-1].kwargs["channels"] == 2
    inp.close()


def test_input_devices_are_listed_apart_from_outputs(sd, world):
    _, ins = outputs.list_devices("input")
    _, outs = outputs.list_devices()
    assert [d["name"] for d in ins] == [ALSA_MIC["name"], "system"]
    assert [d["name"] for d in outs] == [ALSA_OUT["name"], "system"]


# ---------------------------------------------------------------------- device input
def test_device_input_streams_the_chosen_channels_into_its_ring(sd, world):
    clock = Clock()
    inp = make_input("system:5,2", clock)
    with pytest.raises(DeviceError, match="not open yet"):
        _ = inp.ring
    inp.open()
    stream = sd.streams[-1]
    assert stream.kwargs["channels"] == 5 and stream.kwargs["samplerate"] == 16000.0  # device inputs 1..5
    sent = capture(inp)
    assert inp.supervisor.step() == STREAMING
    np.testing.assert_array_equal(inp.ring.read(), sent[:, [4, 1]])
    status = inp.status()
    assert status["state"] == "open" and status["channels"] == [5, 2]
    assert status["device"].startswith("system") and status["overflows"] == 0
    assert status["level_peak"] == [
        pytest.approx(float(np.abs(sent[:, 4]).max())),
        pytest.approx(float(np.abs(sent[:, 1]).max())),
    ]
    inp.close()
    assert inp.status()["state"] == "closed" and stream.calls[-1] == "close"


def test_default_channels_are_the_first_two_inputs(sd, world):
    inp = make_input("system", Clock())
    inp.open()
    assert inp.channels == (1, 2) and inp.ring.channels == 2
    inp.close()


def test_a_lost_input_is_reported_then_reopened_with_the_same_ring(sd, world):
    clock = Clock()
    inp = make_input("USB mic", clock, host_api="ALSA")
    inp.open()
    capture(inp)
    inp.supervisor.step()
    ring = inp.ring
    world.mic_up = False
    sd.streams[-1].device_error()
    clock.advance(0.05)
    assert inp.supervisor.step() == LOST
    assert inp.status()["state"] == "lost" and inp.status()["reason"] == "stream stopped"
    clock.advance(0.3)
    inp.supervisor.step()  # a retry: the microphone is still unplugged
    assert inp.status()["state"] == "retrying" and "no audio input device found" in inp.status()["last_error"]
    world.mic_up = True

    while inp.supervisor.step() != STREAMING:
        clock.advance(0.05)
        beat(inp)
    assert inp.ring is ring and inp.status()["state"] == "open" and inp.restarts == 1
    assert inp.supervisor.recoveries == 1
    inp.close()


def test_an_input_loss_never_rescans_under_a_playing_output(small_bank, sd, world):
    """Pa_Terminate would close the output too: the input reopens on PortAudio as it is."""
    clock = Clock()
    out = SoundDeviceOutput(Engine(small_bank, channels=1), host_api="ALSA", block_size=64, restart=False, clock=clock)
    out.start()
    pump(out)
    out.supervisor.step()
    inp = make_input("USB mic", clock, host_api="ALSA")
    inp.open()
    capture(inp)
    inp.supervisor.step()
    assert out.runtime is inp.runtime  # one PortAudio instance for both
    terminated, out_stream = sd._lib.terminated, sd.streams[0]
    sd.streams[-1].device_error()
    clock.advance(0.05)
    assert inp.supervisor.step() == LOST
    while inp.supervisor.step() != STREAMING:
        clock.advance(0.05)
        pump(out)
        beat(inp)
    assert sd._lib.terminated == terminated  # no re-scan ran under the output
    assert out_stream.active and out_stream.calls == ["start"] and out.supervisor.step() == STREAMING
    inp.close()
    out.stop()


def test_a_dead_jack_server_takes_both_and_one_rescan_brings_both_back(small_bank, sd, world):
    clock = Clock()
    out = SoundDeviceOutput(Engine(small_bank, channels=1), host_api="JACK", block_size=64, restart=False, clock=clock)
    out.start()
    pump(out)
    out.supervisor.step()
    inp = make_input("system:1", clock)
    inp.open()
    capture(inp)
    inp.supervisor.step()
    old_out, old_in = sd.streams[0], sd.streams[1]
    world.jack_up = False
    old_out.jack_server_died()
    old_in.jack_server_died()
    clock.advance(0.05)
    assert out.supervisor.step() == LOST and inp.supervisor.step() == LOST
    assert inp.status()["reason"] == "JACK server shut down"
    for _ in range(20):  # both retry while the server is down
        clock.advance(0.25)
        out.supervisor.step()
        inp.supervisor.step()
    world.jack_up = True
    for _ in range(400):
        clock.advance(0.05)
        states = (out.supervisor.step(), inp.supervisor.step())
        beat(inp)
        pump(out)
        if states == (STREAMING, STREAMING):
            break
    assert (out.state, inp.state) == (STREAMING, STREAMING)
    assert old_out.calls == ["start"] and old_in.calls == ["start"]  # dead JACK streams never called again
    assert out.runtime.generation == 1  # one fresh PortAudio library for the loss of both
    live = [s for s in sd.streams if s.active]
    assert len(live) == 2 and all(s.lib is sd._lib for s in live)
    inp.close()
    out.stop()


def test_exit_never_waits_for_another_streams_retry(sd, world):
    """A retry holds the runtime's lock while it re-scans and opens: shutdown does not wait for it."""
    runtime = shared_runtime(sd)
    held, release = threading.Event(), threading.Event()

    def retry() -> None:
        with runtime.lock:
            held.set()
            release.wait()

    thread = threading.Thread(target=retry)
    thread.start()
    try:
        held.wait()
        assert returns(runtime.shutdown, "shutdown while a retry holds the lock") is False
        assert sd._initialized == 0  # sounddevice's exit hook disarmed: the process ends with os._exit
    finally:
        release.set()
        thread.join()


# ---------------------------------------------------------------------- file input
class FrameClock:
    def __init__(self) -> None:
        self.frame = 0

    def __call__(self) -> int:
        return self.frame


def write_wav(path, fs, data) -> None:
    wavfile.write(path, fs, np.asarray(data, dtype=np.float32))


def drain(inp: FileInput, clock: FrameClock, frames: int, step: int = 4096) -> np.ndarray:
    """Advance the output clock to ``frames`` and collect what the file input delivers."""
    got = []
    while clock.frame < frames:
        clock.frame = min(frames, clock.frame + step)
        target = clock.frame + inp.lead_frames
        wait_until(lambda: inp.ring.frames_written >= target or inp.ended.is_set(), "the file input keeps up")
        got.append(inp.ring.read())
    got.append(inp.ring.read())
    return np.concatenate(got)


def test_file_input_is_resampled_exactly_and_paced_by_the_output_clock(tmp_path):
    rng = np.random.default_rng(5)
    x = rng.uniform(-0.5, 0.5, (44100, 3)).astype(np.float32)
    path = tmp_path / "in.wav"
    write_wav(path, 44100, x)
    clock = FrameClock()
    inp = FileInput(path, fs=48000.0, frame_clock=clock, channels=[3, 1], lead_frames=256, block_frames=1000)
    inp.open()
    try:
        wait_until(lambda: inp.ring.frames_written >= 256, "the lead is fed")
        assert inp.ring.frames_written == 256  # no further than the output clock allows
        got = drain(inp, clock, 30000)
        assert got.shape[0] == 30256  # output clock + lead, exactly
        ref = resample_poly(x[:, [2, 0]].astype(np.float64), 160, 147, axis=0).astype(np.float32)
        np.testing.assert_allclose(got, ref[:30256], atol=1e-6)
        assert inp.status()["state"] == "open" and inp.status()["channels"] == [3, 1]
        rest = drain(inp, clock, 60000)
        assert inp.ended.wait(10) and inp.status()["state"] == "ended"
        np.testing.assert_allclose(np.concatenate([got, rest]), ref, atol=1e-6)  # all of it, then nothing
    finally:
        inp.close()


def test_file_input_loops_without_a_gap(tmp_path):
    x = np.sin(2 * np.pi * 100 * np.arange(4800) / 48000).astype(np.float32)  # 10 periods: loops seamlessly
    path = tmp_path / "tone.wav"
    write_wav(path, 48000, x)
    clock = FrameClock()
    inp = FileInput(path, fs=48000.0, frame_clock=clock, loop=True)
    inp.open()
    try:
        got = drain(inp, clock, 4800 * 3 + 100)
    finally:
        inp.close()
    np.testing.assert_array_equal(got[: 4800 * 3, 0], np.tile(x, 3))
    assert inp.loops >= 3 and inp.status()["state"] == "closed"


def test_file_input_takes_8_channels_at_192k(tmp_path):
    rng = np.random.default_rng(9)
    x = rng.uniform(-0.1, 0.1, (19200, 8)).astype(np.float32)
    path = tmp_path / "multi.wav"
    write_wav(path, 192000, x)
    clock = FrameClock()
    inp = FileInput(path, fs=48000.0, frame_clock=clock, lead_frames=0)
    assert inp.ring.channels == 8 and inp.file_fs == 192000
    inp.open()
    try:
        got = drain(inp, clock, 4800)
    finally:
        inp.close()
    ref = resample_poly(x.astype(np.float64), 1, 4, axis=0)
    np.testing.assert_allclose(got, ref, atol=1e-6)


def test_file_input_plays_a_flac_like_the_wav_it_holds(tmp_path):
    import soundfile

    rng = np.random.default_rng(13)
    x = np.round(rng.uniform(-0.5, 0.5, (9600, 2)) * 2**15) / 2**15  # 16-bit values: FLAC keeps them exactly
    path = tmp_path / "scan.flac"
    soundfile.write(path, x, 96000, subtype="PCM_16")
    clock = FrameClock()
    inp = FileInput(path, fs=48000.0, frame_clock=clock)
    assert inp.file_fs == 96000 and inp.ring.channels == 2
    inp.open()
    try:
        got = drain(inp, clock, 4800)
    finally:
        inp.close()
    np.testing.assert_allclose(got, resample_poly(x, 1, 2, axis=0), atol=1e-6)


def test_bad_files_and_channels_are_one_clear_error(tmp_path):
    path = tmp_path / "stereo.wav"
    write_wav(path, 48000, np.zeros((100, 2)))
    with pytest.raises(InputError, match=r"has 2 channels \(1\.\.2\); cannot take channels \[3\]"):
        FileInput(path, fs=48000.0, frame_clock=FrameClock(), channels=[3])
    junk = tmp_path / "junk.wav"
    junk.write_bytes(b"not a wav at all")
    with pytest.raises(InputError, match="junk.wav: not a sound file vibsynth reads"):
        FileInput(junk, fs=48000.0, frame_clock=FrameClock())


def test_level_db():
    assert level_db(1.0) == 0.0 and level_db(0.5) == pytest.approx(-6.02, abs=0.01)
    assert level_db(0.0) == -120.0 and level_db(float("nan")) == -120.0
