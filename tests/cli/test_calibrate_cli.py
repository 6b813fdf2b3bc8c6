"""``vibsynth calibrate response`` end to end without a sound card: the devices faked, the recording synthetic.

What stays real: the command line, the sweep plan, the analysis and its checks, the profile writing
and the one-line error. The fakes stand in for PortAudio (the output and the input streams) and for
``_record``, which returns what a voice coil through a sensor would have recorded for the stimulus
it is given, its response cut when the test says (the actuator's signal lost mid-sweep).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from vibsynth.cli import main
from vibsynth.settings.actuators import read_actuator_profile

FS = 48000.0
#: The loop's latency in the synthetic recordings (samples).
DELAY = 480


def voice_coil() -> tuple[np.ndarray, np.ndarray]:
    """A 65 Hz, Q 3 resonant high-pass at -6 dB (the acceleration of a voice coil per unit of drive)."""
    w0 = 2 * math.pi * 65.0 / FS
    alpha = math.sin(w0) / 6.0
    c = math.cos(w0)
    b = np.array([(1 + c) / 2, -(1 + c), (1 + c) / 2]) * 10 ** (-6.0 / 20)
    a = np.array([1 + alpha, -2 * c, 1 - alpha])
    return b / a[0], a / a[0]


class FakeOutput:
    state, state_reason = "streaming", ""

    def __init__(self, engine, **kwargs) -> None:
        pass

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def shutdown_portaudio(self) -> bool:
        return True

    def _device_label(self) -> str:
        return "fake output"


class FakeInput:
    def __init__(self, spec, **kwargs) -> None:
        pass

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def status(self) -> dict:
        return {"state": "open", "device": "system"}


@pytest.fixture
def calibrate(monkeypatch, tmp_path):
    """Runs the command with the fakes; ``lost_at`` = (sweep, seconds) where the actuator's signal stops."""
    import vibsynth.app.calibrate as app
    import vibsynth.engine.engine as engine_module
    import vibsynth.engine.inputs as inputs
    import vibsynth.engine.outputs as outputs

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.delenv("VIBSYNTH_CONFIG", raising=False)
    monkeypatch.setattr(app, "_input_channels", lambda spec, host_api: ("system", 1, 2))
    monkeypatch.setattr(engine_module, "Engine", lambda *args, **kwargs: object())
    monkeypatch.setattr(outputs, "SoundDeviceOutput", FakeOutput)
    monkeypatch.setattr(inputs, "SoundDeviceInput", FakeInput)
    state: dict = {}

    def record(engine, output, source, stimulus, channel, fs):
        pre = int(app.PRE_S * fs)
        need = stimulus.size + pre + int((app.MAX_LATENCY_S + 0.1) * fs)
        b, a = voice_coil()
        response = np.zeros(need)
        response[pre + DELAY : pre + DELAY + stimulus.size] = signal.lfilter(b, a, stimulus)[: need - pre - DELAY]
        lost = state.get("lost_at")
        if lost is not None:
            sweep, seconds = lost
            plan_start = state["starts"][sweep - 1]
            response[pre + DELAY + plan_start + int(round(seconds * fs)) :] = 0.0
        noise = 1e-4 * np.random.default_rng(12).standard_normal((need, 2))
        data = noise + np.stack([response, np.zeros(need)], axis=1)
        return data.astype(np.float32), 0.0

    monkeypatch.setattr(app, "_record", record)

    def run(out: Path, lost_at: tuple[int, float] | None = None) -> int:
        from vibsynth.dsp.measure import SweepPlan

        state["lost_at"] = lost_at
        state["starts"] = SweepPlan(fs=FS, seconds=1.0, n_sweeps=3).starts()
        args = ["calibrate", "response", "--channel", "1", "--input", "system:1", "--seconds", "1", "-o", str(out)]
        return main([*args, "--set", "audio.rate=48000"])

    return run


def test_a_signal_lost_mid_sweep_names_when_and_leaves_the_existing_profile_byte_identical(calibrate, tmp_path, capsys):
    out = tmp_path / "coil.yaml"
    assert calibrate(out) == 0  # the same fakes, nothing lost: a profile is written
    model = read_actuator_profile(out)
    assert model.absolute and 55 < np.array(model.response)[np.argmax(np.array(model.response)[:, 1]), 0] < 75
    before = out.read_bytes()
    files = sorted(p.name for p in tmp_path.iterdir())
    capsys.readouterr()

    assert calibrate(out, lost_at=(2, 0.5)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        "vibsynth: error: the response on system:1 stopped 0.5 s into sweep 2 of 3 (at 100 Hz) and did not come back: "
        "the input or the actuator was lost (check the sensor's cable and power, the amplifier and the actuator's "
        "wiring, then measure again); no profile was written"
    ), err
    assert not any("Traceback" in line for line in err)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == files  # no temporary file left either
