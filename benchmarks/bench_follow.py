"""Benchmark of the follow tracker against Android's HapticGenerator: latency, CPU, voice vs impact.

The peer is Android's HapticGenerator audio effect (AOSP ``libeffects/hapticgenerator``, 2020-),
implemented here in Python/SciPy from its published signal chain, with its default parameters:
a 2nd-order high-pass at 50 Hz and low-pass at 9 kHz, a half-wave rectifier, high-pass 60 Hz and
low-passes at 700, 400 and 500 Hz (each a cascade of two matched-z one-pole sections), a resonator
at the motor's resonance (150 Hz, Q 1: zero at DC, pole pair), a slow envelope normaliser
(``x * (env + 0.01) ** -0.8``, env = |x| through a 5 Hz one-pole), a notch at the resonance (zero
Q 8, pole Q 4, unit gain at DC) and a distortion (``x = 0.3 x; x^3 / (0.1 + x^2)``, a 300 Hz
2nd-order low-pass, soft limit ``1.5 x / (1 + |x|)``). Its output drives the motor directly.

Measured on the same inputs, at 48 kHz:

* latency: an input noise burst's level steps by 20 dB (up and down); time until the output's
  80-200 Hz level (the paper's intensity) is half-way in dB. The tracker: its commanded level
  (frames as they complete, live; the engine adds its block and a one-hop glide). The peer:
  its output measured by a zero-phase 80-200 Hz filter in 2 ms windows (no measuring delay).
  Onset -> transient: the tracker's first frame with an onset after a burst out of silence.
* CPU: seconds of input per second of processing for one channel fed in 128-frame blocks (the
  live block), one core; the peer in the same Python/SciPy form (on Android it is C).
* voice vs impact: speech (espeak-ng, and a recorded voice from alsa-utils when installed) and an
  impact-like burst, each at -23 LUFS (BS.1770); how much weaker the voice shakes, as the mean
  80-200 Hz output power over the sound (dB, voice minus impact; more negative = voice held down).

Run: ``python benchmarks/bench_follow.py [--quick]``. Prints a table, writes
``benchmarks/results/bench_follow.json``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.dsp.follow import Tracker, default_params, follow  # noqa: E402
from vibsynth.dsp.follow.loudness import integrated_loudness  # noqa: E402
from vibsynth.dsp.follow.vibration import intensity_sos  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402
from vibsynth.formats.recordings import read_recording  # noqa: E402

FS = 48000.0
BLOCK = 128


# --------------------------------------------------------------------------- the peer
def _one_pole_pole(corner_hz: float, fs: float) -> float:
    return float(np.exp(-2 * np.pi * corner_hz / fs))  # matched z of s = -2 pi f


def _lpf1(corner: float, fs: float) -> tuple[list[float], list[float]]:
    p = _one_pole_pole(corner, fs)
    return [0.5 * (1 - p), 0.5 * (1 - p)], [1.0, -p]


def _hpf1(corner: float, fs: float) -> tuple[list[float], list[float]]:
    p = _one_pole_pole(corner, fs)
    return [0.5 * (1 + p), -0.5 * (1 + p)], [1.0, -p]


def _sos2(first: tuple[list[float], list[float]]) -> np.ndarray:
    """Two identical first-order sections as one biquad row."""
    b, a = first
    return np.array([*np.polymul(b, b), *np.polymul(a, a)])


def _complex_pole(freq: float, q: float, fs: float) -> tuple[float, float]:
    w = 2 * np.pi * freq
    radius = np.exp(-w / (2 * q) / fs)
    return radius * np.cos(w / fs), radius * np.sin(w / fs)


class HapticGeneratorPeer:
    """Android HapticGenerator's default chain at ``fs`` (one channel), block by block."""

    def __init__(self, fs: float, resonance: float = 150.0) -> None:
        self.fs = fs
        pre = np.array([_sos2(_hpf1(50.0, fs)), _sos2(_lpf1(9000.0, fs))])
        post = [_sos2(_hpf1(60.0, fs))] + [_sos2(_lpf1(f, fs)) for f in (700.0, 400.0, 500.0)]
        re, im = _complex_pole(resonance, 1.0, fs)
        post.append(np.array([1.0, -1.0, 0.0, 1.0, -2 * re, re * re + im * im]))  # resonator, zero at DC
        self.pre = pre
        self.post = np.array(post)
        zr, zi = _complex_pole(resonance, 8.0, fs)
        pr, pi = _complex_pole(resonance, 4.0, fs)
        z1, z2, p1, p2 = -2 * zr, zr * zr + zi * zi, -2 * pr, pr * pr + pi * pi
        norm = (1 + p1 + p2) / (1 + z1 + z2)
        self.notch = np.array([[norm, z1 * norm, z2 * norm, 1.0, p1, p2]])
        self.env_lp = _lpf1(5.0, fs)
        self.dist_lp = np.array([_sos2(_lpf1(300.0, fs))])
        self.zi = {
            "pre": np.zeros((2, 2)),
            "post": np.zeros((5, 2)),
            "env": np.zeros(1),
            "notch": np.zeros((1, 2)),
            "dist": np.zeros((1, 2)),
        }

    def process(self, x: np.ndarray) -> np.ndarray:
        y, self.zi["pre"] = signal.sosfilt(self.pre, x, zi=self.zi["pre"])
        y = np.maximum(y, 0.0)  # the "ramp": half-wave rectifier
        y, self.zi["post"] = signal.sosfilt(self.post, y, zi=self.zi["post"])
        env, self.zi["env"] = signal.lfilter(*self.env_lp, np.abs(y), zi=self.zi["env"])
        y = y * (env + 0.01) ** -0.8  # slow envelope normaliser (an AGC)
        y, self.zi["notch"] = signal.sosfilt(self.notch, y, zi=self.zi["notch"])
        g = 0.3 * y
        y, self.zi["dist"] = signal.sosfilt(self.dist_lp, g**3 / (0.1 + g * g), zi=self.zi["dist"])
        return 1.5 * y / (1.0 + np.abs(y))


# --------------------------------------------------------------------------- measures
def band_level_db(y: np.ndarray, fs: float, window_s: float = 0.002) -> tuple[np.ndarray, np.ndarray]:
    """Zero-phase 80-200 Hz band level in short windows: (centre times, dB)."""
    band = signal.sosfiltfilt(intensity_sos(fs), y)
    n = int(window_s * fs)
    frames = (band[: band.size // n * n] ** 2).reshape(-1, n).mean(axis=1)
    return (np.arange(frames.size) + 0.5) * n / fs, 10 * np.log10(frames + 1e-30)


def half_step_ms(times: np.ndarray, level: np.ndarray, t_step: float, before: float, after: float) -> float:
    """Milliseconds from ``t_step`` until ``level`` crosses half-way (dB) from ``before`` to ``after``."""
    mid = 0.5 * (before + after)
    later = times >= t_step
    crossed = (level >= mid) if after > before else (level <= mid)
    idx = np.flatnonzero(later & crossed)
    return float((times[idx[0]] - t_step) * 1e3) if idx.size else float("nan")


def step_signal(rng: np.random.Generator, steps: int = 10) -> tuple[np.ndarray, list[tuple[float, float, float]]]:
    """Noise alternating between two levels 20 dB apart every 0.4 s; the steps' (time, from, to) dB."""
    seg = int(0.4 * FS)
    gains = [0.01 if i % 2 == 0 else 0.1 for i in range(steps + 1)]
    x = np.concatenate([g * rng.standard_normal(seg) for g in gains])
    return x, [((i + 1) * 0.4, 20 * np.log10(gains[i]), 20 * np.log10(gains[i + 1])) for i in range(steps)]


def latency(basis, rng) -> dict:
    x, steps = step_signal(rng)
    out: dict = {}
    for mode in ("vibration", "audio"):
        frames = Tracker(fs=FS, params=default_params(mode), basis=basis).process(x)
        t, lv = frames.end_sample / FS, np.where(frames.intensity > 0, frames.intensity * 40.0, -np.inf)
        out[f"vibsynth {mode}"] = [
            half_step_ms(t, lv, ts, _steady(t, lv, ts - 0.1, ts), _steady(t, lv, ts + 0.2, ts + 0.35))
            for ts, _, _ in steps
        ]
    y = HapticGeneratorPeer(FS).process(x)
    t, lv = band_level_db(y, FS)
    out["HapticGenerator"] = [
        half_step_ms(t, lv, ts, _steady(t, lv, ts - 0.1, ts), _steady(t, lv, ts + 0.2, ts + 0.35)) for ts, _, _ in steps
    ]
    # onset -> transient: bursts out of silence
    z = np.zeros(int(3 * FS))
    starts = [0.5, 1.3, 2.1]
    for s in starts:
        burst = impact(FS, int(s * 10), 0.3) * 0.3
        z[int(s * FS) : int(s * FS) + burst.size] += burst
    frames = Tracker(fs=FS, params=default_params("audio"), basis=basis).process(z)
    onset_t = frames.end_sample[frames.onset_strength > 0] / FS
    out["onset->transient audio"] = [float((onset_t[onset_t >= s][0] - s) * 1e3) for s in starts]
    return out


def _steady(t: np.ndarray, lv: np.ndarray, a: float, b: float) -> float:
    inside = lv[(t >= a) & (t < b)]
    return float(10 * np.log10(np.mean(10 ** (inside / 10))))


def cpu(basis, rng, seconds: float) -> dict:
    x = 0.05 * rng.standard_normal(int(seconds * FS))
    blocks = [x[i : i + BLOCK] for i in range(0, x.size, BLOCK)]
    out = {}
    for name, make in (
        ("vibsynth vibration", lambda: Tracker(fs=FS, params=default_params("vibration"), basis=basis).process),
        ("vibsynth audio", lambda: Tracker(fs=FS, params=default_params("audio", "effects"), basis=basis).process),
        ("HapticGenerator (Python)", lambda: HapticGeneratorPeer(FS).process),
    ):
        run = make()
        started = time.process_time()
        for b in blocks:
            run(b)
        out[name] = seconds / (time.process_time() - started)
    return out


def impact(fs: float, seed: int, seconds: float = 1.0) -> np.ndarray:
    t = np.arange(int(seconds * fs)) / fs
    x = np.random.default_rng(seed).standard_normal(t.size) * np.exp(-t / 0.15)
    return signal.sosfilt(signal.butter(2, 800.0, fs=fs, output="sos"), x)


def at_lufs(x: np.ndarray, fs: float, target: float = -23.0) -> np.ndarray:
    return x * 10 ** ((target - integrated_loudness(x, fs)) / 20)


def voices(tmp: Path) -> dict[str, np.ndarray]:
    found = {}
    if shutil.which("espeak-ng"):
        wav = tmp / "speech.wav"
        text = "The quick brown fox jumps over the lazy dog. Haptics should not shake for voices."
        subprocess.run(["espeak-ng", "-w", str(wav), text], check=True, capture_output=True)
        found["espeak-ng speech"] = wav
    alsa = Path("/usr/share/sounds/alsa/Front_Left.wav")
    if alsa.exists():
        found["recorded voice (alsa)"] = alsa
    out = {}
    for name, path in found.items():
        rec = read_recording(path)
        out[name] = signal.resample_poly(rec.samples, int(FS), int(rec.fs)) if rec.fs != FS else rec.samples
    return out


def mean_power_db(level_db: np.ndarray) -> float:
    return float(10 * np.log10(np.mean(10 ** (np.asarray(level_db) / 10)) + 1e-30))


def voice_vs_impact(basis, tmp: Path) -> dict:
    hit = at_lufs(impact(FS, 7), FS)
    out = {}
    for name, v in voices(tmp).items():
        v = at_lufs(v, FS)
        row = {}
        for focus in ("all", "effects"):
            shakes = []
            for x in (v, hit):
                r = follow(x, FS, mode="audio", focus=focus, basis=basis)
                shakes.append(mean_power_db(np.where(r.intensity > 0, r.output_level_db, -300.0)))
            row[f"vibsynth {focus}"] = shakes[0] - shakes[1]
        peer = [mean_power_db(band_level_db(HapticGeneratorPeer(FS).process(x), FS)[1]) for x in (v, hit)]
        row["HapticGenerator"] = peer[0] - peer[1]
        out[name] = row
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter CPU run")
    args = parser.parse_args()
    basis = default_basis()
    rng = np.random.default_rng(2026)
    lat = latency(basis, rng)
    speed = cpu(basis, rng, 5.0 if args.quick else 20.0)
    with tempfile.TemporaryDirectory() as tmp:
        vs = voice_vs_impact(basis, Path(tmp))
    trackers = {
        name: Tracker(fs=FS, params=default_params(mode), basis=basis)
        for name, mode in (("vibsynth vibration", "vibration"), ("vibsynth audio", "audio"))
    }
    print(f"{'':26} {'step->half ms: median':>22} {'up':>5} {'down':>5} {'max':>5} {'CPU x real time':>16}")
    for name in ("vibsynth vibration", "vibsynth audio", "HapticGenerator"):
        cpu_key = name if name in speed else "HapticGenerator (Python)"
        v = np.array(lat[name])
        up, down = np.nanmedian(v[0::2]), np.nanmedian(v[1::2])
        print(f"{name:26} {np.nanmedian(v):22.1f} {up:5.1f} {down:5.1f} {np.nanmax(v):5.1f} {speed[cpu_key]:16.0f}")
    o = np.array(lat["onset->transient audio"])
    print(f"onset -> transient (audio): median {np.median(o):.1f} ms, max {np.max(o):.1f} ms")
    for name, t in trackers.items():
        print(f"{name}: hop {t.hop} samples ({1e3 * t.hop / FS:.2f} ms), stated latency {t.latency} samples")
    print("\nvoice vs impact of equal loudness (-23 LUFS): voice's mean 80-200 Hz output power minus the impact's, dB")
    for name, row in vs.items():
        print(f"  {name:24} " + "  ".join(f"{k} {v:+6.1f}" for k, v in row.items()))
    result = {
        "fs": FS,
        "block": BLOCK,
        "latency_ms": lat,
        "latency_median_ms": {k: float(np.nanmedian(v)) for k, v in lat.items()},
        "latency_up_down_median_ms": {
            k: [float(np.nanmedian(v[0::2])), float(np.nanmedian(v[1::2]))] for k, v in lat.items() if "onset" not in k
        },
        "cpu_x_realtime_per_channel": speed,
        "stated_latency_samples": {k: t.latency for k, t in trackers.items()},
        "hop_samples": {k: t.hop for k, t in trackers.items()},
        "voice_minus_impact_db": vs,
    }
    out = ROOT / "benchmarks" / "results" / "bench_follow.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
