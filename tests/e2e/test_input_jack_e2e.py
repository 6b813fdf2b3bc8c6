"""End to end: the input path on real PortAudio -> JACK (dummy driver), beside the output.

* The input's ports appear beside the output's, in PortAudio's one JACK client (``jack_lsp``);
  a JACK client plays a counter signal (each sample names the JACK frame it was played on)
  into them, and what the ring returns is that counter, sample for sample, on every channel,
  with no overflow while the reader keeps up.
* An input opened beside the output: windows with and without it, alternated; every input
  callback runs, nothing overflows, the audio does not collapse (the callback's cost and the
  underflows are printed; their figures beside the machine's noise are the benchmarks').
* The JACK server killed and restarted: the input reports ``lost``, then ``open`` again, and
  carries the counter sample-exact again, while the output comes back too (one process:
  ``vibsynth`` in a child with its own private server, so this one's libjack stays clean).

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_input_jack_e2e.py -q -s``.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.jackutil import (
    COUNTER_PERIOD,
    JackPlayer,
    assert_no_collapse,
    counter_frames,
    jack_ports,
    new_ports,
    portaudio_input_ports,
    portaudio_output_ports,
)
from tests.e2e.test_device_loss_e2e import DETECT_WITHIN_S, RESUME_WITHIN_S
from tests.e2e.test_device_loss_e2e import jack as private_jack  # noqa: F401 - a fixture: a killable server
from vibsynth.app.service import build_engine
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.input_ring import frame_offset, output_stamp
from vibsynth.engine.inputs import SoundDeviceInput
from vibsynth.engine.outputs import SoundDeviceOutput
from vibsynth.settings.config import load_config

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[2]
FS = 48000
WINDOW_S = float(os.environ.get("VIBSYNTH_INPUT_WINDOW_S", "2.5"))
#: Windows of each kind (alone, with the input), alternated.
ROUNDS = 4


def exact_but_for_xruns(bad: int, checked: int, disturbances: int, channels: int) -> bool:
    """A received counter is exact, but for the cycles JACK itself lost (xruns, the Python player's late cycles).

    Each lost cycle breaks the counter once per channel (a block skipped): at most a few wrong steps each.
    """
    return checked > 0 and (bad == 0 or bad <= 2 * channels * disturbances)


def counter_errors(x: np.ndarray) -> tuple[int, int]:
    """(steps checked, steps that are not +1 frame) of a received counter, per channel; from its first sample on."""
    checked = bad = 0
    for k in range(x.shape[1]):
        frames = counter_frames(x[:, k], k)
        steps = np.diff(frames) % COUNTER_PERIOD
        checked += steps.size
        bad += int(np.count_nonzero(steps != 1))
    return checked, bad


class Reader(threading.Thread):
    """Reads an input's ring every few ms, as the follow worker will."""

    def __init__(self, inp: SoundDeviceInput) -> None:
        super().__init__(daemon=True)
        self.inp = inp
        self.blocks: list[np.ndarray] = []
        self.stop = threading.Event()
        self.keep = True

    def run(self) -> None:
        while not self.stop.wait(0.005):
            x = self.inp.ring.read()
            if self.keep and x.shape[0]:
                self.blocks.append(x)

    def data(self) -> np.ndarray:
        return np.concatenate(self.blocks) if self.blocks else np.zeros((0, self.inp.ring.channels), np.float32)


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    cache = tmp_path_factory.mktemp("bank-cache")
    return load_config(overrides={"audio": {"rate": FS, "block_size": 128}, "bank": {"cache_dir": str(cache)}}).settings


@pytest.fixture
def output(jack_server, config):
    engine = build_engine(config)
    out = SoundDeviceOutput(engine, host_api="JACK", block_size=128, latency="low")
    out.start()
    yield out
    out.stop()


def test_input_ports_stand_beside_the_output_and_carry_a_signal_sample_exact(output):
    inp = SoundDeviceInput("system:1,2", fs=FS, host_api="JACK", block_size=128)
    before = jack_ports()
    inp.open_ports()
    try:
        targets = new_ports(before)
        assert len(targets) == 2, targets  # in_N, in_N+1 of the client "PortAudio" ...
        with JackPlayer(n_ports=2) as player:
            assert set(targets) <= set(portaudio_input_ports(player.client))
            assert portaudio_output_ports(player.client)  # ... beside the output's out_M
            player.connect(targets)
            player.play()
            inp.open()
            reader = Reader(inp)
            reader.start()
            time.sleep(3.0)
            reader.stop.set()
            reader.join()
            x = reader.data()
            gaps = player.gaps
        status = inp.status()
        xruns = status["input_overflows"]
        first = np.argmax(np.any(x != 0, axis=1))  # before the player's first cycle: silence
        checked, bad = counter_errors(x[first:])
        stamp = inp.ring.stamp()
        print(
            f"\ninput: {x.shape[0]} frames read in 3 s, {checked} counter steps checked, {bad} wrong, player gaps "
            f"{gaps}; overflows {status['overflows']}, dropped {status['dropped_frames']}, PortAudio input "
            f"overflows {status['input_overflows']}; callback load {100 * status['callback_load']:.3f} % of the "
            f"period; last block: ADC {stamp.adc_time:.6f} s, callback {stamp.current_time:.6f} s "
            f"(capture latency {1000 * (stamp.current_time - stamp.adc_time):.2f} ms)"
        )
        assert x.shape[0] > 2.5 * FS and checked > 2 * 2.5 * FS
        assert exact_but_for_xruns(bad, checked, gaps + xruns, 2), (bad, gaps, xruns)
        assert status["overflows"] == status["dropped_frames"] == 0
        assert status["state"] == "open" and status["level_db"] == pytest.approx(-6.02, abs=0.01)
    finally:
        inp.close()
    assert inp.status()["state"] == "closed"
    assert output.state == "streaming"


def _late_portaudio_cycles() -> int:
    """Cycles jackd logged PortAudio's client as not finished (with_jack.sh's log), -1 without the log."""
    log = Path(f"/tmp/jackd-{os.environ.get('JACK_DEFAULT_SERVER', '')}.log")
    return log.read_text(errors="replace").count("client = PortAudio was not finished") if log.is_file() else -1


def test_an_input_beside_the_output_runs_every_callback(output):
    """Windows with the output alone and with an input (and its reader) beside it, alternated: the
    machine's own load drifts during a run, so each kind gets the same share of it."""
    engine = output.engine
    time.sleep(0.5)  # past the start-up blocks
    totals = {"alone": 0, "input": 0}
    late = {"alone": 0, "input": 0}
    callbacks = overflows = 0
    loads: list[float] = []
    peaks: list[float] = []
    for _ in range(ROUNDS):
        for kind in ("alone", "input"):
            inp = reader = None
            if kind == "input":
                inp = SoundDeviceInput("system:1,2", fs=FS, host_api="JACK", block_size=128)
                inp.open()
                reader = Reader(inp)
                reader.keep = False
                reader.start()
            try:
                time.sleep(0.5)  # past opening
                u0, l0 = engine.stats.underflows, _late_portaudio_cycles()
                c0 = inp.ring.callbacks if inp else 0
                if inp:
                    inp.ring.take_load_peak()
                time.sleep(WINDOW_S)
                totals[kind] += engine.stats.underflows - u0
                late[kind] += _late_portaudio_cycles() - l0
                if inp:
                    callbacks += inp.ring.callbacks - c0
                    overflows += inp.ring.overflows
                    loads.append(inp.ring.load_avg)
                    peaks.append(inp.ring.take_load_peak())
            finally:
                if reader is not None:
                    reader.stop.set()
                    reader.join()
                if inp is not None:
                    inp.close()
    period_us = 1e6 * 128 / FS
    load = float(np.mean(loads))
    print(
        f"\nunderflows over {ROUNDS} x {WINDOW_S:g} s: output alone {totals['alone']}, with a 2-channel input "
        f"{totals['input']} (jackd: PortAudio's client late {late['alone']} vs {late['input']} cycles); input "
        f"callbacks {callbacks}, overflows {overflows}; input callback {load * period_us:.2f} us per 128-frame "
        f"block on average ({100 * load:.3f} % of the period), peak {max(peaks) * period_us:.1f} us"
    )
    assert_no_collapse(totals["alone"], ROUNDS * WINDOW_S, "the output alone")
    assert_no_collapse(totals["input"], ROUNDS * WINDOW_S, "the output with a 2-channel input")
    assert overflows == 0 and callbacks > 0.9 * ROUNDS * WINDOW_S * FS / 128


#: Windows of the loop test: one JACK lost cycles in is measured again, up to this many in all.
LOOP_ATTEMPTS = 5


def test_a_loop_from_the_output_back_to_the_input_is_bit_exact_and_its_latency_measured(output):
    """Calibration's measurement loop, inside JACK: PortAudio:out_0 -> PortAudio:in_0.

    The engine's own output (its tap) comes back in the ring bit for bit, a whole number of frames
    later; the block stamps of the two streams predict that delay (callback times: the loop never
    leaves the server), so a loop through an actuator and a sensor is that delay plus its own.
    """
    engine = output.engine
    engine.submit(SetKnob("intensity", 0.8, glide_s=0.0))
    for attempt in range(1, LOOP_ATTEMPTS + 1):  # a window JACK itself lost cycles in is measured again
        inp = SoundDeviceInput("system:1", fs=FS, host_api="JACK", block_size=128)
        before = jack_ports()
        inp.open_ports()
        try:
            (port,) = new_ports(before)
            with JackPlayer(n_ports=1) as wiring:  # a client that only wires the loop
                wiring.client.connect(portaudio_output_ports(wiring.client)[0], port)
                inp.open()
                time.sleep(0.5)
                inp.ring.skip()
                time.sleep(0.25)
                first = inp.ring.frames_read
                x = inp.ring.read()[:, 0]
                tap = np.empty((32768, engine.channels), np.float32)
                tap_end = engine._core.read_tap(tap)
                offsets = [frame_offset(output_stamp(engine), inp.ring.stamp(), FS, device_times=False)]
                for _ in range(20):
                    time.sleep(0.01)
                    offsets.append(frame_offset(output_stamp(engine), inp.ring.stamp(), FS, device_times=False))
        finally:
            inp.close()
        assert inp.ring.dropped_frames == 0 and x.size > 0.2 * FS and np.abs(x).max() > 1e-3
        if not inp.ring.input_overflows:
            break
        print(f"\nwindow {attempt}: JACK lost {inp.ring.input_overflows} cycles (xruns): no exact loop, measured again")
    else:
        pytest.skip(f"JACK lost cycles (xruns) in each of {LOOP_ATTEMPTS} windows: no exact loop to check")
    y = tap[:, 0]
    y_first = tap_end - y.size  # output frame of y[0]
    # the lag D (input frame - output frame) at which the input is the output, bit for bit
    corr = np.correlate(y.astype(np.float64), x[:2048].astype(np.float64), mode="valid")
    start = int(np.argmax(corr))
    lag = first - (y_first + start)
    seg = x[: min(x.size, y.size - start)]
    np.testing.assert_array_equal(seg, y[start : start + seg.size])
    predicted = float(np.median(offsets))
    spread = float(np.ptp(offsets))
    print(
        f"\nloop out_0 -> in_0 inside JACK: input frame = output frame + {lag}, bit for bit (the counters "
        f"start apart); the block stamps predict {predicted:.1f} (spread {spread:.1f} over 21 pairs of blocks)"
    )
    # the loop adds nothing inside the server: the stamps alone give the offset, to a few frames
    assert abs(lag - predicted) <= 8 + spread


def test_a_file_input_runs_in_step_with_the_output_clock(output, tmp_path):
    """FileInput is paced by the engine's frames on JACK, not by the wall clock: always `lead` ahead."""
    from scipy.io import wavfile
    from scipy.signal import resample_poly

    from vibsynth.engine.inputs import FileInput

    rng = np.random.default_rng(4)
    x = rng.uniform(-0.5, 0.5, (3 * 44100, 2)).astype(np.float32)
    path = tmp_path / "demo.wav"
    wavfile.write(path, 44100, x)
    engine = output.engine
    inp = FileInput(path, fs=FS, frame_clock=lambda: int(engine.frame_position), lead_frames=512)
    got, ahead = [], []
    inp.open()
    try:
        while inp.start_frame is None:
            time.sleep(0.001)
        start = inp.start_frame
        for _ in range(100):  # 1 s
            time.sleep(0.01)
            ahead.append(inp.ring.frames_captured - (engine.frame_position - start))
            got.append(inp.ring.read())
    finally:
        inp.close()
    got.append(inp.ring.read())
    y = np.concatenate(got)
    ref = resample_poly(x.astype(np.float64), 160, 147, axis=0)[: y.shape[0]]
    print(
        f"\nfile input on the output clock: {y.shape[0]} frames in 1 s; frames ahead of the output: "
        f"median {np.median(ahead):.0f}, min {min(ahead)}, max {max(ahead)} (lead 512)"
    )
    np.testing.assert_allclose(y, ref, atol=1e-6)
    assert 0.9 * FS < y.shape[0] < 1.2 * FS
    # ahead of the output by the lead, less what the output rendered since the feeder's last wake-up
    assert max(ahead) <= 512 and np.median(ahead) > 0


# ---------------------------------------------------------------------- server death
_CHILD = r"""
import json, sys, threading, time
import numpy as np
sys.path.insert(0, sys.argv[2])
from tests.e2e.jackutil import JackPlayer, portaudio_input_ports
from tests.e2e.test_input_jack_e2e import counter_errors
from vibsynth.app.service import build_engine
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.input_ring import frame_offset, output_stamp
from vibsynth.engine.inputs import SoundDeviceInput
from vibsynth.engine.outputs import SoundDeviceOutput
from vibsynth.engine.supervisor import hard_exit
from vibsynth.settings.config import load_config

cfg = load_config(overrides={"audio": {"rate": 48000, "block_size": 128}, "bank": {"cache_dir": sys.argv[1]}}).settings
engine = build_engine(cfg)
out = SoundDeviceOutput(engine, host_api="JACK", block_size=128)
out.start()
inp = SoundDeviceInput("system:1,2", fs=48000, host_api="JACK", block_size=128)
inp.open()
lock = threading.Lock()
got = []
player = [None]
players = []
xruns = [0]

def read():
    while True:
        x = inp.ring.read()
        if x.shape[0]:
            with lock:
                got.append(x)
        time.sleep(0.005)

def commands():
    for line in sys.stdin:
        cmd = line.strip()
        if cmd == "play":  # an earlier player may be on a dead server: kept, never called again
            p = JackPlayer(n_ports=2)
            p.connect(portaudio_input_ports(p.client))
            with lock:
                got.clear()
                xruns[0] = inp.ring.input_overflows
            p.play()
            player[0] = p
            players.append(p)
        elif cmd == "check":
            with lock:
                x = np.concatenate(got) if got else np.zeros((0, 2), np.float32)
            nz = np.flatnonzero(np.any(x != 0, axis=1))
            checked, bad = counter_errors(x[nz[0]:]) if nz.size else (0, 0)
            lost = (player[0].gaps if player[0] else 0) + inp.ring.input_overflows - xruns[0]
            print(json.dumps({"check": [int(checked), int(bad), int(lost)]}), flush=True)
        elif cmd == "quit":
            hard_exit(0)

threading.Thread(target=read, daemon=True).start()
threading.Thread(target=commands, daemon=True).start()
while True:
    s = inp.status()
    print(json.dumps({"t": time.monotonic(), "output": out.state, "input": s["state"], "reason": s["reason"],
                      "frames": s["frames"], "engine_frames": engine.frame_position,
                      "recovered_after_s": s["recovered_after_s"]}), flush=True)
    time.sleep(0.02)
"""


class Child:
    """The vibsynth side (output + input + a reader) in its own process; JSON lines out, commands in."""

    def __init__(self, env: dict[str, str], cache: Path, log: Path) -> None:
        self.log = log
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(cache), str(ROOT)],
            cwd=ROOT,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=open(log, "w"),  # noqa: SIM115 - closed with the process
            text=True,
        )
        self.lines: queue.Queue[dict] = queue.Queue()
        self.last: dict = {}
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                self.lines.put(json.loads(line))
            except json.JSONDecodeError:
                pass

    def send(self, cmd: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(cmd + "\n")
        self.proc.stdin.flush()

    def wait(self, predicate, timeout: float, what: str) -> tuple[dict, float]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            if "t" in line:
                self.last = line
            if predicate(line):
                return line, time.monotonic()
        raise AssertionError(f"{what}: not seen in {timeout:g} s; last {self.last}\n{self.log.read_text()[-3000:]}")

    def check(self) -> tuple[int, int, int]:
        self.send("check")
        line, _ = self.wait(lambda d: "check" in d, 10.0, "a counter check")
        return tuple(line["check"])

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.send("quit")
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


def test_input_reports_a_dead_server_and_recovers_with_the_output(request, tmp_path, config):
    jack = request.getfixturevalue("private_jack")  # its own jackd (dummy driver, 2 capture ports), killed below
    child = Child(dict(jack.env, PYTHONPATH=str(ROOT)), Path(config.bank.cache_dir), tmp_path / "child.log")
    try:
        child.wait(lambda d: d.get("input") == "open" and d.get("output") == "streaming", 120.0, "both streaming")
        child.send("play")
        time.sleep(1.0)
        checked, bad, gaps = child.check()
        assert checked > 48000 and exact_but_for_xruns(bad, checked, gaps, 2), (checked, bad, gaps)

        killed = jack.kill()
        line, seen = child.wait(lambda d: d.get("input") in ("lost", "retrying"), 5.0, "the input lost")
        detect = seen - killed
        assert line["reason"] == "JACK server shut down"
        child.wait(lambda d: d.get("output") == "device lost", 5.0, "the output lost")
        time.sleep(2.0)
        assert child.last["input"] in ("lost", "retrying")

        back = jack.start()
        line, seen = child.wait(
            lambda d: d.get("input") == "open" and d.get("output") == "streaming", RESUME_WITHIN_S + 5.0, "both back"
        )
        resumed = seen - back
        frames = line["frames"]
        line, _ = child.wait(lambda d: d.get("frames", 0) > frames + 4800, 5.0, "input frames flowing again")
        engine_frames = line["engine_frames"]
        child.wait(lambda d: d.get("engine_frames", 0) > engine_frames + 4800, 5.0, "the output rendering again")
        child.send("play")  # a new player on the new server, into the reopened input's new ports
        time.sleep(1.0)
        checked2, bad2, gaps2 = child.check()
        print(
            f"\nJACK killed -> input 'lost' in {1000 * detect:.0f} ms; server back -> input and output open again in "
            f"{resumed:.2f} s (input's own recovery: {line['recovered_after_s']:.2f} s after the loss); counter "
            f"before {checked} steps, {bad} wrong; after {checked2} steps, {bad2} wrong (JACK cycles lost "
            f"{gaps}, {gaps2})"
        )
        assert detect < DETECT_WITHIN_S and resumed < RESUME_WITHIN_S
        assert checked2 > 48000 and exact_but_for_xruns(bad2, checked2, gaps2, 2), (checked2, bad2, gaps2)
        log = child.log.read_text()
        assert "audio input device lost: JACK server shut down" in log and "audio input device back" in log
        assert "Traceback" not in log
    finally:
        child.close()
