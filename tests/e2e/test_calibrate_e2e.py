"""``vibsynth calibrate response`` on the JACK dummy server, through a simulated actuator.

The simulated actuator is a JACK client of this test process: its input is fed by the
measuring process' ``PortAudio:out_N``, its output feeds one ``PortAudio:in_K``; in between,
a numpy/scipy process callback applies a known response (a voice coil's 2nd-order
resonance, like the paper's HapCoil-One at 65 Hz, an overall sensitivity) and adds seeded
noise. The measuring command runs in a child process (its own GIL; this client's Python
callback never delays its streams).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy import signal

from tests.e2e.jackutil import require_jack

pytestmark = pytest.mark.e2e

REPO = Path(__file__).resolve().parents[2]


def resonance_sos(f0: float, q: float, gain_db: float, fs: float) -> np.ndarray:
    """A voice coil's acceleration per volt: a resonant 2nd-order high-pass (RBJ), times a sensitivity."""
    w0 = 2 * np.pi * f0 / fs
    alpha = np.sin(w0) / (2 * q)
    c = np.cos(w0)
    b = np.array([(1 + c) / 2, -(1 + c), (1 + c) / 2]) * 10 ** (gain_db / 20)
    a = np.array([1 + alpha, -2 * c, 1 - alpha])
    return np.concatenate([b / a[0], a / a[0]])[np.newaxis, :]


def response_db(sos: np.ndarray, freqs: np.ndarray, fs: float) -> np.ndarray:
    _, h = signal.sosfreqz(sos, worN=freqs, fs=fs)
    return 20 * np.log10(np.abs(h))


#: Cycles the simulated actuator's callback runs before it says it is ready (0.1 s at 48 kHz, 128 frames).
WARM_CYCLES = 40


def run_simulated_actuator(name: str, sos: np.ndarray, noise_rms: float, seed: int) -> None:
    """The simulated actuator's process: a JACK client ``name`` (``in`` -> response + noise -> ``out``).

    Its main thread only waits on stdin (no other Python thread may hold the GIL the real-time
    process callback needs). ``record N FILE`` records the next N frames of its output (what
    the skin gets) to ``FILE.npy`` and answers ``recorded GAPS``; when stdin closes it prints
    the JACK cycles it missed and exits.
    """
    import jack

    client = jack.Client(name, no_start_server=True, servername=os.environ.get("JACK_DEFAULT_SERVER"))
    inport = client.inports.register("in")
    outport = client.outports.register("out")
    zi = np.zeros((sos.shape[0], 2))
    noise = (noise_rms * np.random.default_rng(seed).standard_normal(1 << 18)).astype(np.float32)
    state: dict = {"pos": 0, "gaps": 0, "next": None, "rec": None, "at": 0, "cycles": 0}
    full = threading.Event()  # the main thread waits without the GIL while the callback records
    warm = threading.Event()

    def process(frames: int) -> None:
        nonlocal zi
        now = client.last_frame_time
        state["cycles"] += 1
        if state["cycles"] == WARM_CYCLES:
            warm.set()
        if state["next"] is not None and now != state["next"]:
            state["gaps"] += 1  # a cycle this Python client missed: a hole in the instrument
        state["next"] = now + frames
        y, zi = signal.sosfilt(sos, inport.get_array(), zi=zi)
        pos = state["pos"]
        if pos + frames > noise.size:
            pos = 0
        out = outport.get_array()
        out[:] = y + noise[pos : pos + frames]
        state["pos"] = pos + frames
        rec = state["rec"]
        if rec is not None and state["at"] < rec.size:
            n = min(frames, rec.size - state["at"])
            rec[state["at"] : state["at"] + n] = out[:n]
            state["at"] += n
            if state["at"] == rec.size:
                full.set()

    client.set_process_callback(process)
    client.activate()
    # Ready once the callback runs in the graph, its first (slow) calls behind it: a measurement
    # started at once could meet those first cycles.
    if not warm.wait(10.0):
        raise SystemExit("the simulated actuator's process callback did not run")
    print("ready", flush=True)
    for line in sys.stdin:
        _, frames, path = line.split()
        buf = np.zeros(int(frames), dtype=np.float32)
        gaps = state["gaps"]
        full.clear()
        state["at"], state["rec"] = 0, buf
        full.wait()
        state["rec"] = None
        np.save(path, buf)
        print(f"recorded {state['gaps'] - gaps}", flush=True)
    client.deactivate()
    client.close()
    print(f"gaps {state['gaps']}", flush=True)


class SimulatedActuator:
    """A simulated actuator in its own process, patched between the measuring process' ports.

    ``PortAudio:out_<channel>`` -> the actuator -> the ``input_index``-th PortAudio input port
    (0: none, the actuator's ``out`` is captured by the test), connected by a patch-bay client
    of this process as soon as the ports appear: those of a PortAudio client made after the
    actuator (the measuring process'), never those that existed before it.
    """

    _count = 0

    def __init__(
        self, sos: np.ndarray, *, noise_rms: float, seed: int, channel: int = 1, input_index: int = 1, wait: bool = True
    ) -> None:
        """``wait=False``: return once the child is started; :meth:`wait_ready` before using it."""
        import jack

        SimulatedActuator._count += 1
        self.name = f"sim-actuator-{os.getpid()}-{SimulatedActuator._count}"
        self.fs = 48000.0
        args = [self.name, ",".join(repr(float(v)) for v in sos.ravel()), repr(noise_rms), str(seed)]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.e2e.test_calibrate_e2e", *args],
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._ready = False
        if wait:
            self.wait_ready()
        self.gaps = 0
        self.patch = jack.Client(
            f"{self.name}-patch", no_start_server=True, servername=os.environ.get("JACK_DEFAULT_SERVER")
        )
        self.fs = float(self.patch.samplerate)
        self.channel, self.input_index = channel, input_index
        # PortAudio ports of other processes that exist now (a serve of an earlier test still
        # closing, this test process' own PortAudio client): never patched. By identity, not name:
        # the measuring process' client may get a name that one of them held.
        self._stale = {p.uuid for p in self.patch.get_ports("PortAudio", is_audio=True)}
        self._stop = threading.Event()
        self._watch = threading.Thread(target=self._connect_loop, daemon=True)
        self._watch.start()

    def wait_ready(self) -> None:
        """Until the child's JACK client runs (numpy, scipy and jack take a few seconds to import)."""
        if not self._ready:
            assert self.proc.stdout is not None and self.proc.stdout.readline().strip() == "ready"
            self._ready = True

    @classmethod
    def many(cls, soses: list[np.ndarray], **each: Any) -> list[SimulatedActuator]:
        """One actuator per response, ``channel`` 1, 2, ...: their children start side by side."""
        sims = [cls(sos, channel=k + 1, wait=False, **dict(each, seed=each["seed"] + k)) for k, sos in enumerate(soses)]
        for sim in sims:
            sim.wait_ready()
        return sims

    def _connect_loop(self) -> None:
        connected = None
        client = self.patch

        def order(name: str) -> tuple[int, str]:
            return (len(name), name)  # out_2 before out_10

        while not self._stop.is_set():
            try:
                ports = [p for p in client.get_ports("PortAudio", is_audio=True) if p.uuid not in self._stale]
                outs = sorted((p.name for p in ports if p.is_output), key=order)
                ins = sorted((p.name for p in ports if p.is_input), key=order)
                want = None
                if len(outs) >= self.channel and len(ins) >= self.input_index:
                    want = (outs[self.channel - 1], ins[self.input_index - 1] if self.input_index else "")
                if want is not None and want != connected:
                    client.connect(want[0], f"{self.name}:in")
                    if want[1]:
                        client.connect(f"{self.name}:out", want[1])
                connected = want
            except Exception:  # noqa: BLE001 - ports vanish while the child exits
                connected = None
            time.sleep(0.005)

    def record(self, seconds: float, path: Path) -> tuple[np.ndarray, int]:
        """The actuator's output over the next ``seconds`` (gap-free unless it says so): (samples, missed cycles)."""
        self.wait_ready()
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(f"record {int(seconds * self.fs)} {path}\n")
        self.proc.stdin.flush()
        answer = self.proc.stdout.readline().split()
        assert answer[0] == "recorded", answer
        return np.load(path).astype(np.float64), int(answer[1])

    def close(self) -> None:
        self._stop.set()
        self._watch.join(timeout=2)
        self.patch.close()
        out, _ = self.proc.communicate(timeout=10)
        self.gaps = int(out.split()[-1]) if out.strip() else -1


def env_of(tmp_path: Path) -> dict[str, str]:
    return dict(os.environ, XDG_CONFIG_HOME=str(tmp_path / "config"), HOME=str(tmp_path))


def calibrate(
    tmp_path: Path, *extra: str, name: str = "sim", out: str | None = None
) -> subprocess.CompletedProcess[str]:
    env = env_of(tmp_path)
    cmd = [
        sys.executable, "-m", "vibsynth", "calibrate", "response", "--input", "system:1",
        "--set", "audio.host_api=JACK", "-o", out or str(tmp_path / f"{name}.yaml"), *extra,
    ]  # fmt: skip
    if "--channels" not in extra and "--channel" not in extra:
        cmd += ["--channel", "1"]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=REPO)


def read_profile(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    doc = yaml.safe_load(path.read_text())
    pts = np.array(doc["response"])
    return pts[:, 0], pts[:, 1], doc


def fine_response(freqs_pts: np.ndarray, db_pts: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    return np.interp(np.log(freqs), np.log(freqs_pts), db_pts)


@pytest.fixture
def jack_ready() -> None:
    require_jack()


def test_simulated_actuator_measured_within_1_db_and_runs_agree(jack_ready, tmp_path):
    sos = resonance_sos(65.0, 3.0, -6.0, 48000.0)
    sim = SimulatedActuator(sos, noise_rms=1e-4, seed=1)
    try:
        runs = []
        for k in range(3):
            proc = calibrate(tmp_path, "--seconds", "2", "--sweeps", "2", name=f"run{k}")
            assert proc.returncode == 0, proc.stderr
            runs.append(read_profile(tmp_path / f"run{k}.yaml"))
    finally:
        sim.close()
    print(f"simulated actuator missed {sim.gaps} JACK cycles")
    f = np.geomspace(20, 800, 200)
    truth = response_db(sos, f, sim.fs)
    measured = np.stack([fine_response(p[0], p[1], f) for p in runs])
    err = measured - truth
    print(f"max |error| 20-800 Hz per run: {np.abs(err).max(axis=1).round(3)} dB")
    print(f"at {f[np.abs(err).argmax(axis=1)].round(0)} Hz")
    apart = np.abs(measured - measured.mean(axis=0)).max()
    print(f"largest distance of a run from the three runs' mean: {apart:.3f} dB")
    assert np.abs(err).max() <= 1.0
    assert apart <= 0.3
    doc = runs[0][2]
    prov = doc["provenance"]
    assert doc["absolute"] is True and doc["rate"] == 48000 and prov["rate_hz"] == 48000
    assert prov["snr_db_min"] > 40 and prov["repeatability_db"] < 0.3
    assert 0 <= prov["latency_ms"] < 50
    assert len(prov["bands_db"]) == 30 and prov["input_channel"] == 1 and prov["output_channel"] == 1
    lo, hi = doc["band_hz"]
    assert 40 < lo < hi < 400


@pytest.mark.parametrize(
    ("case", "gain_db", "noise", "input_index", "message"),
    [
        ("no signal", None, 0.0, 1, "no signal on input"),
        ("clipping", 30.0, 1e-4, 1, "clipped during the sweep"),
        ("wrong channel", -6.0, 1e-4, 2, "came back on input channel 2"),
        ("noise", -30.0, 0.2, 1, "background noise"),
    ],
)
def test_bad_input_one_message_and_no_profile_changed(jack_ready, tmp_path, case, gain_db, noise, input_index, message):
    existing = tmp_path / "sim.yaml"
    existing.write_text("name: sim\nresponse: [[10, 0.0], [1000, 0.0]]\n")
    before = existing.read_bytes()
    sim = None
    if gain_db is not None:
        sim = SimulatedActuator(
            resonance_sos(65.0, 3.0, gain_db, 48000.0), noise_rms=noise, seed=2, input_index=input_index
        )
    try:
        proc = calibrate(tmp_path, "--seconds", "1", "--sweeps", "1")
    finally:
        if sim is not None:
            sim.close()
    assert proc.returncode != 0
    errors = [line for line in proc.stderr.splitlines() if line.startswith("vibsynth: error:")]
    assert len(errors) == 1 and message in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert existing.read_bytes() == before


if __name__ == "__main__":  # the simulated actuator's process (see SimulatedActuator)
    _name, _sos, _noise, _seed = sys.argv[1:5]
    run_simulated_actuator(
        _name, np.array([float(v) for v in _sos.split(",")]).reshape(-1, 6), float(_noise), int(_seed)
    )


# ------------------------------------------------------------------ calibrated intensity
#: Three actuators: (resonance Hz, Q, sensitivity dB): +-6 dB apart, resonances an octave apart.
ACTUATORS = [(45.0, 2.0, -6.0), (65.0, 3.0, 0.0), (100.0, 4.0, 6.0)]


def uncalibrated(tmp_path: Path, sos: np.ndarray) -> np.ndarray:
    """What an actuator of response ``sos`` does with the flat profile's texture (intensity 0.8,
    balance +1): rendered once offline, then filtered by the response. The actuator is linear, so
    this is what playing it through it records (its 1e-5 noise aside: the same levels and balances
    as three serves and captures, which this saves)."""
    path = tmp_path / "flat.wav"
    if not path.exists():
        cmd = [
            sys.executable, "-m", "vibsynth", "render", "--balance", "1", "--intensity", "0.8",
            "--seconds", "4", "--rate", "48000", "-o", str(path), "-q",
        ]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env_of(tmp_path), cwd=REPO)
        assert done.returncode == 0, done.stderr
    from scipy.io import wavfile

    rate, x = wavfile.read(path)
    assert rate == 48000
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    # the texture loops seamlessly: the second of two periods is the actuator's steady state (the
    # first holds the filter's start-up transient, which alone moved the low bands by up to 11 dB)
    return signal.sosfilt(sos, np.tile(x, 2))[x.size :]


def test_jack_server_lost_mid_sweep_one_message_no_profile(tmp_path):
    """The whole audio server dies mid-sweep (input and output lost): one message, no profile changed.

    No JACK client of this process touches the killable server (libjack serves one server per
    process, and the other tests use theirs): the sweep's progress line tells when to kill it.
    """
    from tests.e2e.test_device_loss_e2e import JackServer

    require_jack()
    server = JackServer(f"vibsynth-cal-loss-{os.getpid()}", tmp_path / "jackd.log")
    server.start()
    existing = tmp_path / "sim.yaml"
    existing.write_text("name: sim\nresponse: [[10, 0.0], [1000, 0.0]]\n")
    before = existing.read_bytes()
    try:
        env = dict(env_of(tmp_path), JACK_DEFAULT_SERVER=server.name)
        cmd = [
            sys.executable, "-m", "vibsynth", "calibrate", "response", "--channel", "1", "--input", "system:1",
            "--set", "audio.host_api=JACK", "-o", str(existing), "--seconds", "4", "--sweeps", "3",
        ]  # fmt: skip
        proc = subprocess.Popen(cmd, env=env, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert proc.stderr is not None
        first = proc.stderr.readline()
        assert "sweeps of 4 s" in first, first
        time.sleep(2.5)  # the lead second, then into the first sweep
        server.kill()
        out, err = proc.communicate(timeout=60)
    finally:
        server.stop()
    assert proc.returncode != 0
    errors = [line for line in err.splitlines() if line.startswith("vibsynth: error:")]
    assert len(errors) == 1 and "lost during the sweep" in errors[0], err
    assert "Traceback" not in err
    assert existing.read_bytes() == before


def test_three_actuators_measured_in_one_run_then_feel_the_same(jack_ready, tmp_path):
    """``calibrate response --channels all`` measures three different actuators (one channel plays at a
    time, all feed input 1: JACK sums them), each profile within 1 dB of its truth; then one serve with
    ``actuator.channel_profiles: coil-ch{n}`` makes them feel the same, where the flat texture does not."""
    from tests.e2e.test_calibrate_channels_e2e import felt_by_each
    from vibsynth.dsp.analysis import analyze
    from vibsynth.dsp.intensity import intensity_level_db
    from vibsynth.formats.basis_file import default_basis

    soses = [resonance_sos(f0, q, gain, 48000.0) for f0, q, gain in ACTUATORS]
    sims = SimulatedActuator.many(soses, noise_rms=1e-5, seed=10)
    try:
        proc = calibrate(
            tmp_path, "--channels", "all", "--set", f"audio.channels={len(sims)}",
            "--seconds", "2", "--sweeps", "2", "--level", "-24", out="coil",
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        for sim in sims:
            sim.input_index = 0  # serve has no input: the actuators only record
        felt = felt_by_each(tmp_path, sims, "--set", "actuator.channel_profiles=coil-ch{n}")
    finally:
        for sim in sims:
            sim.close()
    f = np.geomspace(20, 800, 200)
    folder = tmp_path / "config" / "vibsynth" / "actuators"
    for k, sos in enumerate(soses):
        pf, pdb, doc = read_profile(folder / f"coil-ch{k + 1}.yaml")
        err = np.abs(fine_response(pf, pdb, f) - response_db(sos, f, 48000.0)).max()
        print(f"channel {k + 1}: max |error| 20-800 Hz {err:.3f} dB, band {doc['band_hz']}")
        assert err <= 1.0 and doc["name"] == f"coil-ch{k + 1}" and doc["provenance"]["output_channel"] == k + 1
    basis = default_basis()
    rows = []
    for k, sos in enumerate(soses):
        for name, y in (("uncalibrated", uncalibrated(tmp_path, sos)), ("calibrated", felt[k])):
            a = analyze(y, fs=48000.0, basis=basis)
            rows.append((k, name, intensity_level_db(y, fs=48000.0), a.balance))
    for k, name, level, balance in rows:
        print(f"actuator {ACTUATORS[k]}: {name:12s} 80-200 Hz level {level:7.2f} dB, balance {balance:+.3f}")
    cal_levels = np.array([r[2] for r in rows if r[1] == "calibrated"])
    cal_bal = np.array([r[3] for r in rows if r[1] == "calibrated"])
    raw_levels = np.array([r[2] for r in rows if r[1] == "uncalibrated"])
    raw_bal = np.array([r[3] for r in rows if r[1] == "uncalibrated"])
    print(f"uncalibrated: levels {np.ptp(raw_levels):.2f} dB apart, balances {np.ptp(raw_bal):.2f} apart")
    print(f"calibrated: levels within {np.abs(cal_levels - cal_levels.mean()).max():.3f} dB of their mean, "
          f"balances within {np.abs(cal_bal - cal_bal.mean()).max():.3f}")  # fmt: skip
    assert np.abs(cal_levels - cal_levels.mean()).max() <= 0.5
    assert np.abs(cal_bal - cal_bal.mean()).max() <= 0.1
    assert np.ptp(raw_levels) > 3.0 and np.ptp(raw_bal) > 0.3  # the test can tell: uncalibrated they differ
