"""Calibration checks and profiles without a sound card: synthetic recordings through app.calibrate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from vibsynth.app.calibrate import CalibrationResult, check_measurement, profile_document, profile_path, write_profiles
from vibsynth.dsp.measure import SweepPlan, measure_recording
from vibsynth.errors import InputError, ParameterError
from vibsynth.settings.actuators import profile_rate_problem, read_actuator_profile

FS = 48000.0
PLAN = SweepPlan(fs=FS, seconds=1.0, n_sweeps=3)


def voice_coil(gain_db: float = -6.0):
    w0 = 2 * math.pi * 65.0 / FS
    alpha = math.sin(w0) / 6.0
    c = math.cos(w0)
    b = np.array([(1 + c) / 2, -(1 + c), (1 + c) / 2]) * 10 ** (gain_db / 20)
    a = np.array([1 + alpha, -2 * c, 1 - alpha])
    return b / a[0], a / a[0]


def recording(gain_db: float | None = -6.0, noise: float = 1e-4, seed: int = 0) -> np.ndarray:
    x = PLAN.stimulus()
    y = np.zeros(x.size + 30000)
    if gain_db is not None:
        b, a = voice_coil(gain_db)
        y[100 : 100 + x.size] = signal.lfilter(b, a, x)
    return y + noise * np.random.default_rng(seed).standard_normal(y.size)


def measured(**kw) -> object:
    return measure_recording(recording(**kw), PLAN, max_latency_s=0.45)


def test_a_good_recording_passes_and_makes_a_valid_absolute_profile(tmp_path):
    m = measured()
    check_measurement(m, input_label="system:1", level_dbfs=-12)
    result = CalibrationResult(1, m, PLAN, "jack", "system", 1, latency_frames=100.0)
    doc = profile_document(result, "coil", version="test")
    assert doc["absolute"] is True and doc["rate"] == 48000
    assert doc["provenance"]["latency_ms"] == pytest.approx(100 / 48, abs=0.01)
    assert doc["provenance"]["snr_db_min"] > 40
    lo, hi = doc["band_hz"]
    assert 40 < lo < 150 < hi < 400
    (path,) = write_profiles([result], str(tmp_path / "coil.yaml"), user_dir=tmp_path)
    model = read_actuator_profile(path)
    pts = np.array(model.response)
    f0 = pts[np.argmax(pts[:, 1]), 0]
    assert 55 < f0 < 75 and model.absolute and model.rate == 48000 and model.provenance["sweeps"] == 3
    # the response is absolute: the sensitivity (-6 dB) and the Q=3 peak (+9.5 dB) show
    assert pts[-1, 1] == pytest.approx(-6.0, abs=0.1) and pts[:, 1].max() == pytest.approx(3.6, abs=0.3)


@pytest.mark.parametrize(
    ("kwargs", "others", "message"),
    [
        ({"gain_db": 40.0}, None, "clipped during the sweep"),
        ({"gain_db": None, "noise": 1e-6}, None, "no signal on input system:1"),
        ({"gain_db": None, "noise": 1e-6}, {"gain_db": -6.0}, "came back on input channel 2"),
        ({"gain_db": -40.0, "noise": 0.05}, None, "background noise on system:1"),
        ({"gain_db": -20.0, "noise": 1e-3}, None, "too close to the sweep"),
    ],
)
def test_bad_recordings_refused_with_one_message(kwargs, others, message):
    m = measured(**kwargs)
    extra = None if others is None else {2: measured(**others)}
    with pytest.raises(InputError, match=message):
        check_measurement(m, input_label="system:1", level_dbfs=-12, others=extra)


def test_profile_names_and_paths(tmp_path):
    assert profile_path("coil", 3, several=True, user_dir=tmp_path) == ("coil-ch3", tmp_path / "coil-ch3.yaml")
    assert profile_path(None, 1, several=False, user_dir=tmp_path) == ("measured", tmp_path / "measured.yaml")
    assert profile_path(str(tmp_path / "x.yaml"), 1, several=False, user_dir=tmp_path)[1] == tmp_path / "x.yaml"
    with pytest.raises(ParameterError):
        profile_path("bad name!", 1, several=False, user_dir=tmp_path)


def test_a_profile_from_another_rate_is_refused_with_one_message():
    profile = {"name": "coil", "rate": 44100}
    assert profile_rate_problem(profile, 44100) is None
    assert profile_rate_problem({"name": "flat", "rate": None}, 48000) is None
    text = profile_rate_problem(profile, 48000)
    assert text is not None and "measured at 44100 Hz but audio.rate is 48000 Hz" in text


def test_a_config_naming_a_profile_from_another_rate_fails_to_load(tmp_path, monkeypatch):
    from vibsynth.errors import ConfigError
    from vibsynth.settings.config import load_config

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    folder = tmp_path / "vibsynth" / "actuators"
    folder.mkdir(parents=True)
    (folder / "coil.yaml").write_text("absolute: true\nrate: 44100\nresponse: [[10, -30.0], [1000, 0.0]]\n")
    assert load_config(overrides={"actuator.profile": "coil", "audio.rate": 44100}).settings.actuator.profile == "coil"
    with pytest.raises(ConfigError, match="measured at 44100 Hz but audio.rate is 48000 Hz"):
        load_config(overrides={"actuator.profile": "coil", "audio.rate": 48000})


class _FakeRing:
    """An input ring that delivers ``frames_until_loss`` frames, then nothing (the device went away)."""

    def __init__(self, frames_until_loss: int) -> None:
        from vibsynth.engine.input_ring import BlockStamp

        self.left = frames_until_loss
        self.frames_read = 0
        self._stamp = BlockStamp(0, 0.0, 1.0, 0.0, 1.0)

    def stamp(self):
        return self._stamp

    def skip(self) -> int:
        return 0

    def read(self, max_frames=None):
        n = min(4800, self.left)
        self.left -= n
        self.frames_read += n
        return np.zeros((n, 2), dtype=np.float32)


class _FakeSource:
    def __init__(self, ring: _FakeRing) -> None:
        self.ring = ring

    def status(self):
        lost = self.ring.left == 0
        return {
            "state": "lost" if lost else "open",
            "device": "system",
            "reason": "JACK server shut down" if lost else "",
        }


class _FakeEngine:
    frame_position = 0

    class _core:  # noqa: N801 - stands in for the compiled core
        @staticmethod
        def output_stamp():
            return (0, 0.0, 1.0, 0.0, 1.0)

    def play_buffer(self, samples, *, channels, at_frame):
        self.played = (samples.size, channels, at_frame)
        return 1


class _FakeOutput:
    state = "streaming"
    state_reason = ""


def test_an_input_lost_mid_sweep_stops_the_run_with_one_message():
    from vibsynth.app.calibrate import _record

    ring = _FakeRing(frames_until_loss=48000)  # one second of the stimulus, then the device is gone
    engine = _FakeEngine()
    with pytest.raises(InputError, match="input device 'system' was lost during the sweep .JACK server shut down."):
        _record(engine, _FakeOutput(), _FakeSource(ring), PLAN.stimulus(), 0, FS)
    assert engine.played[1] == [0]


def test_an_output_lost_mid_sweep_stops_the_run():
    from vibsynth.app.calibrate import _record
    from vibsynth.errors import DeviceError

    output = _FakeOutput()
    output.state, output.state_reason = "device lost", "JACK server shut down"
    with pytest.raises(DeviceError, match="output device was lost during the sweep"):
        _record(_FakeEngine(), output, _FakeSource(_FakeRing(10**7)), PLAN.stimulus(), 0, FS)


def test_a_measured_iso_curve_moves_the_band_and_keeps_the_response(tmp_path):
    from vibsynth.app.calibrate import apply_iso_curve

    m = measured()
    result = CalibrationResult(1, m, PLAN, "jack", "system", 1, latency_frames=0.0)
    (path,) = write_profiles([result], str(tmp_path / "coil.yaml"), user_dir=tmp_path)
    before = read_actuator_profile(path)
    # a lab's curve whose bottom sits at 300 Hz: the band moves up
    iso_f = np.array([10.0, 30, 100, 300, 1000])
    iso_db = 6.0 * np.log2(iso_f / 300.0) ** 2
    doc = apply_iso_curve(path, iso_f, iso_db, source="lab session s1")
    after = read_actuator_profile(path)
    assert after.response == before.response and after.provenance["sweeps"] == 3
    assert after.band_hz[0] > before.band_hz[0] and after.band_hz == doc["band_hz"]
    assert after.provenance["iso_curve"].startswith("lab session s1")
    assert max(v for _, v in after.weighting) == pytest.approx(0.0, abs=0.2)
    with pytest.raises(ParameterError):
        apply_iso_curve(path, [100.0], [0.0], source="x")
    assert read_actuator_profile(path).band_hz == after.band_hz  # a bad curve wrote nothing


def test_a_response_lost_mid_sweep_is_named_instead_of_the_noise():
    # the case: the actuator's signal gone 0.5 s into the second sweep; the noise did not change
    y = recording(noise=1e-3)
    b, a = voice_coil()
    at = PLAN.starts()[1] + 100 + int(0.5 * FS)
    y[at : 100 + PLAN.stimulus().size] -= signal.lfilter(b, a, PLAN.stimulus())[at - 100 :]
    m = measure_recording(y, PLAN, max_latency_s=0.45)
    with pytest.raises(InputError) as exc:
        check_measurement(m, input_label="system:1", level_dbfs=-12)
    text = str(exc.value)
    assert text.startswith("the response on system:1 stopped 0.5 s into sweep 2 of 3 (at 100 Hz) and did not come ")
    assert "the input or the actuator was lost" in text and "background noise" not in text


def test_a_loss_where_the_response_is_too_weak_to_place_is_given_as_an_interval():
    plan = SweepPlan(fs=FS, seconds=4.0, n_sweeps=3)
    x = plan.stimulus()
    b, a = voice_coil()
    response = np.zeros(x.size + 30000)
    response[100 : 100 + x.size] = signal.lfilter(b, a, x)
    response[plan.starts()[1] + 100 + int(0.5 * FS) :] = 0.0  # at 10.6 Hz: 35 dB down on the coil, under the noise
    y = response + 3.5e-3 * np.random.default_rng(13).standard_normal(response.size)
    m = measure_recording(y, plan, max_latency_s=0.45)
    with pytest.raises(
        InputError, match=r"stopped between 4\.0 s into sweep 1 \(at 2000 Hz\) and 1\.\d s into sweep 2 "
    ):
        check_measurement(m, input_label="system:1", level_dbfs=-12)
