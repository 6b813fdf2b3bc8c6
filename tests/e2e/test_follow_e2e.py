"""End to end: live Follow on real PortAudio -> JACK (dummy driver), input ports beside the output's.

A JACK client plays known signals into serve's input ports (``PortAudio:in_N``), another captures
the actuator output (``PortAudio:out_0``):

* level steps of a 140 Hz tone (20 dB, up and down) -> the output's level reaches half its step;
  the same measurement on direct knob steps (the controller, as OSC does) is the baseline: the
  follow path's added latency is the difference, never a wall time alone;
* clicks -> the output's transient rises, against knob jumps as the baseline;
* following one stereo input: windows of serve alone and following, alternated (the Python
  capture client out of the graph), both far from a collapse (the figures: benchmarks);
* ``vibsynth serve --follow speech.wav`` (espeak-ng): the texture sounds while the voice speaks
  and is silent in its pauses.

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_follow_e2e.py -q -s``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from tests.e2e.jackutil import (
    REALTIME,
    JackCapture,
    JackPlayer,
    JackPlayerProcess,
    assert_no_collapse,
    jack_ports,
    new_ports,
)
from tests.e2e.test_osc_e2e import start_serve, stop_serve
from vibsynth.app.client import Client

pytestmark = [pytest.mark.e2e, REALTIME]

ROOT = Path(__file__).resolve().parents[2]
FS = 48000
STEP_S = 0.3
STEPS = int(os.environ.get("VIBSYNTH_FOLLOW_STEPS", "40"))
LOW_DB, HIGH_DB = -70.0, -50.0  # knob 0.25 and 0.75 at the default mapping: a 20 dB output step
WINDOW_S = 3.0
ROUNDS = 2
#: Steps (or onsets) measured at the least: one whose windows hold a cycle the capture missed is left out.
MIN_MEASURED = 12
#: The measured numbers go to the test's tmp_path; set this to a path (e.g.
#: benchmarks/results/follow_live.json) to keep them for docs/follow.md's live table.
RESULTS_ENV = "VIBSYNTH_FOLLOW_LIVE_JSON"


def serve_env(folder: Path) -> dict[str, str]:
    return dict(
        os.environ,
        XDG_CONFIG_HOME=str(folder / "xdg-config"),
        XDG_DATA_HOME=str(folder / "xdg-data"),
        VIBSYNTH_HOST_API="JACK",
        JACK_NO_AUDIO_RESERVATION="1",
    )


class Served:
    """``vibsynth serve`` on JACK in a child process (its own GIL: the Python JACK clients here keep
    their cycles), following ``device`` (``system:1,2``) in mode ``follow`` unless it is None (``extra``: more
    ``follow:`` keys, indented; ``top``: more top-level sections); ``in_ports`` are its input ports."""

    def __init__(
        self,
        folder: Path,
        follow: str | None = "vibration",
        device: str = "system:1,2",
        extra: str = "",
        channels: int = 1,
        top: str = "",
    ) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        config = (
            f"audio:\n  rate: 48000\n  block_size: 128\n  channels: {channels}\nknobs:\n  glide_ms: 0\n"
            f"studio:\n  enabled: false\n{top}"
        )
        if follow is not None:
            config += f"follow:\n  enabled: true\n  device: '{device}'\n  mode: {follow}\n{extra}"
        before = jack_ports()
        self.proc, self.port = start_serve(folder, output="sounddevice", extra_config=config, env=serve_env(folder))
        try:
            # serve answers OSC before its follower has opened the input: wait for the ports
            deadline = time.monotonic() + 10.0
            self.in_ports = new_ports(before) if follow is not None else []
            while follow is not None and len(self.in_ports) < 2 and time.monotonic() < deadline:
                time.sleep(0.05)
                self.in_ports = new_ports(before)
            self.out_ports = new_ports(before, "out")
            self.client = Client(port=self.port, timeout=2.0)
        except BaseException:
            stop_serve(self.proc)  # never leave a serve on the server for the next tests
            raise

    def close(self) -> None:
        self.client.close()
        stop_serve(self.proc)


@pytest.fixture
def served(jack_server, tmp_path):
    s = Served(tmp_path / "serve")
    try:
        assert len(s.in_ports) == 2, s.in_ports
        yield s
    finally:
        s.close()


class GapCapture(JackCapture):
    """A capture that keeps its samples on the JACK clock: cycles it missed are NaN, not joined over."""

    def _process(self, frames: int) -> None:
        if self._armed and not self._done.is_set() and self.frames_captured and self._next_frame is not None:
            missed = int(self.client.last_frame_time - self._next_frame)
            if 0 < missed:
                pos = self.frames_captured
                n = min(missed, self.data.shape[0] - pos)
                self.data[pos : pos + n] = np.nan
                self.frames_captured = pos + n
                self._next_frame += n
        super()._process(frames)


class TimedPlayer(JackPlayer):
    """A player that notes the JACK frame each cycle of its signal was played at (a missed cycle delays the rest)."""

    def __init__(self, **kw) -> None:
        self.cycles: list[tuple[int, int]] = []
        super().__init__(**kw)

    def _process(self, frames: int) -> None:
        if self._playing:
            self.cycles.append((int(self.client.last_frame_time), self.position))
        super()._process(frames)

    def frame_of(self, index: int) -> int:
        """JACK frame at which signal sample ``index`` was played."""
        starts = np.array([p for _, p in self.cycles])
        k = int(np.searchsorted(starts, index, side="right")) - 1
        frame, position = self.cycles[k]
        return frame + index - position


def frame_rms(x: np.ndarray, hop: int) -> np.ndarray:
    """RMS of consecutive frames of ``hop`` samples."""
    n = x.size // hop
    return np.sqrt(np.mean(np.asarray(x[: n * hop], dtype=np.float64).reshape(n, hop) ** 2, axis=1))


def envelope_db(x: np.ndarray, fs: float, window_s: float = 0.002) -> np.ndarray:
    """The output's level (dB) per sample: centred moving power over ``window_s`` (no delay)."""
    n = max(1, int(window_s * fs))
    power = np.convolve(x.astype(np.float64) ** 2, np.ones(n) / n, mode="same")
    return 10 * np.log10(power + 1e-20)


def half_step_times(env: np.ndarray, fs: float, steps: list[int]) -> list[float]:
    """For each step (sample index), seconds from it to where the level crosses halfway (in dB) to its new plateau."""
    out = []
    pre, post, settle = int(0.1 * fs), int(0.14 * fs), int(0.06 * fs)
    for at in steps:
        if at - pre < 0 or at + post >= env.size:
            continue
        if not np.isfinite(env[at - pre : at + post]).all():
            continue  # a cycle the capture missed: no measurement here
        before = float(np.median(env[at - pre : at - int(0.02 * fs)]))
        after = float(np.median(env[at + settle : at + post]))
        if abs(after - before) < 10.0:
            continue  # not a step (a capture hole)
        mid = 0.5 * (before + after)
        seg = env[at - int(0.005 * fs) : at + settle]
        crossed = seg >= mid if after > before else seg <= mid
        hits = np.flatnonzero(crossed)
        if hits.size:
            out.append((hits[0] - int(0.005 * fs)) / fs)
    return out


def rise_times(env: np.ndarray, fs: float, events: list[int], rise_db: float = 6.0) -> list[float]:
    """For each event, seconds until the level first rises ``rise_db`` over the level just before it."""
    out = []
    for at in events:
        if at - int(0.05 * fs) < 0 or at + int(0.05 * fs) >= env.size:
            continue
        if not np.isfinite(env[at - int(0.05 * fs) : at + int(0.05 * fs)]).all():
            continue  # a cycle the capture missed: no measurement here
        floor = float(np.median(env[at - int(0.05 * fs) : at - int(0.01 * fs)]))
        seg = env[at - int(0.005 * fs) : at + int(0.05 * fs)]
        hits = np.flatnonzero(seg >= floor + rise_db)
        if hits.size:
            out.append((hits[0] - int(0.005 * fs)) / fs)
    return out


def tone_steps(n_steps: int) -> np.ndarray:
    """A 140 Hz tone whose RMS level alternates LOW_DB / HIGH_DB every STEP_S (starts low)."""
    n = int(STEP_S * FS)
    t = np.arange(n * (n_steps + 1)) / FS
    levels = np.repeat([LOW_DB if k % 2 == 0 else HIGH_DB for k in range(n_steps + 1)], n)
    return (np.sqrt(2) * 10 ** (levels / 20) * np.sin(2 * np.pi * 140 * t)).astype(np.float32)


def clicks(n_clicks: int, rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """A quiet noise floor with 3 ms noise clicks 30 dB above it, one every 0.25 s."""
    gap = int(0.25 * FS)
    x = 3e-4 * rng.standard_normal(gap * (n_clicks + 1))
    starts = [gap * (k + 1) - gap // 2 for k in range(n_clicks)]
    for s in starts:
        x[s : s + int(0.003 * FS)] = 1e-2 * rng.standard_normal(int(0.003 * FS))
    return x.astype(np.float32), starts


def play_and_capture(served: Served, signal: np.ndarray, events: list[int]) -> tuple[np.ndarray, list[int], int]:
    """Play ``signal`` (mono, into both inputs) while capturing out_0: (output on the JACK clock, the
    capture indices of the signal's ``events`` (sample indices), the two clients' missed cycles)."""
    seconds = signal.size / FS
    stereo = np.stack([signal, signal], axis=1)
    with TimedPlayer(n_ports=2, signal=stereo) as player, GapCapture(seconds + 1.0) as cap:
        player.connect(served.in_ports)
        cap.connect(served.out_ports[:1])
        cap.arm()
        time.sleep(0.2)
        player.play()
        assert cap.wait(seconds + 10)
        at = [player.frame_of(i) - int(cap.start_frame) for i in events]
        return cap.data[:, 0].copy(), at, cap.gaps + player.gaps


def knob_baseline(served: Served, values: list[float], period_s: float) -> tuple[np.ndarray, list[int], int]:
    """Direct OSC knob moves at known JACK times (follow off on the channel): (out_0, move indices, gaps)."""
    served.client.send("/vibsynth/ch/1/follow", 0)
    served.client.sync()
    with GapCapture(len(values) * period_s + 0.5) as cap:
        cap.connect(served.out_ports[:1])
        cap.arm()
        time.sleep(0.25)
        moves = []
        for value in values:
            moves.append(cap.frame_time_now())
            served.client.send("/vibsynth/intensity", float(value))
            time.sleep(period_s)
        assert cap.wait(len(values) * period_s + 10)
        return cap.data[:, 0].copy(), [m - cap.start_frame for m in moves], cap.gaps


def stats_ms(values: list[float]) -> dict[str, float]:
    ms = 1000 * np.asarray(values)
    return {
        "n": int(ms.size),
        "median": float(np.median(ms)),
        "p99": float(np.percentile(ms, 99)),
        "max": float(ms.max()),
    }


def test_a_level_step_reaches_the_output_within_the_budget_over_a_knob_baseline(served, tmp_path):
    signal = tone_steps(STEPS)
    out, steps_at, gaps = play_and_capture(served, signal, [int(STEP_S * FS) * (k + 1) for k in range(STEPS)])
    follow = half_step_times(envelope_db(out, FS), FS, steps_at)
    # baseline: the same knob values, as direct moves, measured the same way
    values = [0.25 if k % 2 == 0 else 0.75 for k in range(STEPS + 1)]
    base_out, base_at, base_gaps = knob_baseline(served, values, STEP_S)
    baseline = half_step_times(envelope_db(base_out, FS), FS, base_at[1:])
    f, b = stats_ms(follow), stats_ms(baseline)
    added = {"median": f["median"] - b["median"], "p99": f["p99"] - b["p99"]}
    print(
        f"\nlevel step -> half the output step: follow median {f['median']:.1f} ms, p99 {f['p99']:.1f} ms "
        f"(n {f['n']}); direct knob baseline median {b['median']:.1f} ms, p99 {b['p99']:.1f} ms (n {b['n']}); "
        f"added by follow: median {added['median']:.1f} ms, p99 {added['p99']:.1f} ms; capture gaps {gaps}/{base_gaps}"
    )
    _record(tmp_path, "level_step", {"follow_ms": f, "knob_baseline_ms": b, "added_ms": added})
    assert f["n"] >= MIN_MEASURED and b["n"] >= MIN_MEASURED, "the capture missed too many cycles to measure"
    assert f["median"] <= b["median"] + 15.0
    assert f["p99"] <= b["p99"] + 25.0


def test_an_onset_is_a_transient_within_the_budget_over_a_knob_jump_baseline(served, rng, tmp_path):
    signal, starts = clicks(STEPS, rng)
    out, at, gaps = play_and_capture(served, signal, starts)
    follow = rise_times(envelope_db(out, FS), FS, at)
    values = [0.0, 0.25] * STEPS  # jumps from silence-ish to a quiet texture, as a transient rises
    base_out, base_at, base_gaps = knob_baseline(served, values, 0.125)
    baseline = rise_times(envelope_db(base_out, FS), FS, base_at[1::2])
    f, b = stats_ms(follow), stats_ms(baseline)
    print(
        f"\nonset -> transient (+6 dB): follow median {f['median']:.1f} ms, p99 {f['p99']:.1f} ms (n {f['n']}); "
        f"knob jump baseline median {b['median']:.1f} ms (n {b['n']}); added {f['median'] - b['median']:.1f} ms; "
        f"capture gaps {gaps}/{base_gaps}"
    )
    _record(tmp_path, "onset", {"follow_ms": f, "knob_baseline_ms": b, "added_median_ms": f["median"] - b["median"]})
    assert f["n"] >= MIN_MEASURED and b["n"] >= MIN_MEASURED, "the capture missed too many cycles to measure"
    assert f["median"] <= b["median"] + 10.0


def test_following_a_stereo_input_keeps_the_audio_going(jack_server, tmp_path):
    """serve without follow and serve following a stereo input (a tone stepping in level), alternated
    (the machine's load drifts); no capture client in the graph; underflows from serve's /status."""
    signal = tone_steps(int((WINDOW_S + 2) / STEP_S))
    totals = {"alone": 0, "follow": 0}
    for k in range(ROUNDS):
        for kind in ("alone", "follow"):
            served = Served(tmp_path / f"{kind}{k}", follow=None if kind == "alone" else "audio")
            try:
                # the player in its own process: on the synchronous graph an in-process Python client
                # late for the GIL would make every client's cycle late (counted as serve's underflows)
                stereo = np.stack([signal, signal], axis=1)
                with JackPlayerProcess(stereo, served.in_ports, tmp_path):
                    time.sleep(0.5)
                    u0 = served.client.status()["underflows"]
                    time.sleep(WINDOW_S)
                    status = served.client.status()
                    totals[kind] += status["underflows"] - u0
                    if kind == "follow":
                        assert status["follow.gate"] in (0, 1) and "open" in status["follow.device"]
            finally:
                served.close()
    print(
        f"\nunderflows over {ROUNDS} x {WINDOW_S:g} s: serve alone {totals['alone']}, following a stereo input "
        f"{totals['follow']}"
    )
    _record(
        tmp_path,
        "underflows",
        {"alone": totals["alone"], "follow": totals["follow"], "window_s": WINDOW_S, "rounds": ROUNDS},
    )
    assert_no_collapse(totals["alone"], ROUNDS * WINDOW_S, "serve alone")
    assert_no_collapse(totals["follow"], ROUNDS * WINDOW_S, "serve following a stereo input")


def test_serve_follow_a_speech_file_plays_the_voice_and_is_silent_in_its_pauses(jack_server, tmp_path):
    espeak = shutil.which("espeak-ng")
    if espeak is None:
        pytest.skip("espeak-ng is not installed (scripts/setup.sh --test installs it)")
    wav = tmp_path / "speech.wav"
    subprocess.run([espeak, "-w", str(wav), "-g", "40", "Rough gravel. Smooth silk. Fine sand."], check=True)
    fs_in, speech = wavfile.read(wav)
    speech = speech.astype(np.float64) / (32768.0 if speech.dtype == np.int16 else 1.0)
    seconds = speech.size / fs_in
    folder = tmp_path / "serve"
    folder.mkdir()
    cmd = [sys.executable, "-m", "vibsynth", "serve", "--output", "sounddevice", "--no-midi", "--no-studio"]
    cmd += ["--osc-port", "0", "--follow", str(wav), "--follow-mode", "audio", "--seconds", f"{seconds + 4:.1f}"]
    before = jack_ports()
    with JackCapture(seconds + 3.0) as cap:
        proc = subprocess.Popen(
            cmd, cwd=ROOT, env=dict(serve_env(folder), PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE, text=True
        )
        try:
            assert proc.stdout is not None
            for line in proc.stdout:  # the follow line comes once the input runs
                if line.startswith("vibsynth: follow:"):
                    break
            cap.connect(new_ports(before, "out")[:1])
            cap.arm()
            assert cap.wait(seconds + 10)
        finally:
            stop_serve(proc)
    out = cap.data[:, 0]
    # the voice's level and the output's per 10 ms, aligned where their envelopes agree best (the capture
    # started after the file), then compared in 50 ms frames
    voice = frame_rms(speech, int(0.01 * fs_in))
    felt = frame_rms(out, int(0.01 * FS))
    v_db, f_db = (np.maximum(20 * np.log10(a + 1e-9), -80.0) for a in (voice, felt))
    m = min(felt.size, voice.size) - 100
    lag = max(range(101), key=lambda d: float(np.corrcoef(v_db[d : d + m], f_db[:m])[0, 1]))
    voice, felt = frame_rms(speech[int(lag * 0.01 * fs_in) :], int(0.05 * fs_in)), frame_rms(out, int(0.05 * FS))
    n = min(voice.size, felt.size)
    voice, felt = voice[:n], felt[:n]
    loud = voice > 0.3 * voice.max()
    pauses = voice < 1e-4  # espeak's pauses are digital silence
    # 200 ms into a pause (past the audio mode's 120 ms release) and 100 ms before it ends
    quiet = np.array([k >= 4 and bool(pauses[k - 4 : k + 3].all()) for k in range(n)])
    print(
        f"\nspeech ({seconds:.2f} s, {loud.sum()} loud and {quiet.sum()} pause frames of 50 ms, capture "
        f"{lag * 10} ms late): output RMS {20 * np.log10(np.median(felt[loud]) + 1e-12):.1f} dBFS while it "
        f"speaks; in its pauses {20 * np.log10(np.percentile(felt[quiet], 90) + 1e-12):.1f} dBFS (90th percentile), "
        f"{20 * np.log10(np.max(felt[quiet]) + 1e-12):.1f} dBFS at most"
    )
    assert loud.sum() >= 5 and quiet.sum() >= 3
    assert np.median(felt[loud]) > 10 * max(float(np.percentile(felt[quiet], 90)), 1e-6)  # 20 dB down in the pauses


def _record(folder: Path, name: str, values: dict) -> None:
    """Write the measured numbers to ``folder/follow_live.json``, and to ``$VIBSYNTH_FOLLOW_LIVE_JSON`` when set
    (docs/follow.md's live table is made from them); never into the checkout by default."""
    import json

    for path in [
        folder / "follow_live.json",
        *([Path(os.environ[RESULTS_ENV])] if os.environ.get(RESULTS_ENV) else []),
    ]:
        data = json.loads(path.read_text()) if path.is_file() else {}
        data[name] = values
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=2) + "\n")
