"""Benchmark of the time-windowed codec: compression ratio, quality, encode/decode speed.

Cases: synthetic recordings (stationary, intensity step, slow ramp, balance sweep,
bursts with silence) and, when ``../shared/datasets/hatt-psd`` is present, stationary
noises with the full measured spectra of HaTT textures (so the S1 model's own error
shows) and a "scan" over three textures. Prints a table and writes
``benchmarks/results/bench_codec.json``.

Run: ``python benchmarks/bench_codec.py [--quick]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.app import vbt_render  # noqa: E402
from vibsynth.dsp.basis import band_powers_from_psd, to_db  # noqa: E402
from vibsynth.dsp.codec import Quantizer, encode_trajectory, quality  # noqa: E402
from vibsynth.dsp.synthesis import synthesize  # noqa: E402
from vibsynth.formats import vbt  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402
from vibsynth.formats.psd import read_psd_table  # noqa: E402

HATT = ROOT.parent / "shared" / "datasets" / "hatt-psd" / "psd.csv.gz"


def shaped(spec_db, fs, seconds, level, seed):
    return synthesize(
        spec_db, fs=fs, n_samples=int(seconds * fs), level_db=level, rng=np.random.default_rng(seed)
    ).signal


def synthetic_cases(basis, fs):
    m, v1 = basis.mean_db, basis.v1
    yield "stationary", fs, shaped(m + 10 * v1, fs, 10, -40, 1)
    yield "step +10 dB", fs, np.concatenate([shaped(m, fs, 5, -45, 2), shaped(m, fs, 5, -35, 3)])
    ramp = shaped(m, fs, 10, -40, 4) * 10 ** (np.linspace(-10, 10, int(10 * fs)) / 20)
    yield "ramp 20 dB/10 s", fs, ramp
    yield (
        "balance -25..+25",
        fs,
        np.concatenate([shaped(m + t * v1, fs, 2, -40, 5 + i) for i, t in enumerate(np.linspace(-25, 25, 5))]),
    )
    burst = np.concatenate(
        [np.concatenate([shaped(m, fs, 0.5, -38, 20 + i), np.zeros(int(0.5 * fs))]) for i in range(5)]
    )
    yield "bursts + silence", fs, burst


def hatt_cases(basis, fs, n):
    table = read_psd_table(HATT)
    band_db = to_db(band_powers_from_psd(table.freqs_hz, table.psd))
    t1 = basis.scores(band_db)[:, 0]
    picks = np.argsort(t1)[np.linspace(0, t1.size - 1, n).astype(int)]
    for k in picks:
        yield f"HaTT {table.labels[k][:14]} (t1 {t1[k]:+.0f})", fs, shaped(band_db[k], fs, 5, -40, int(k))
    a, b, c = picks[0], picks[len(picks) // 2], picks[-1]
    scan = np.concatenate([shaped(band_db[k], fs, 2, lv, int(k)) for k, lv in ((a, -42), (b, -36), (c, -40))])
    yield "HaTT scan of 3 textures", fs, scan


def run_case(name, fs, x, basis, bits, cache):
    t0 = time.perf_counter()
    traj = encode_trajectory(x, fs=fs, basis=basis)
    q = Quantizer.fit(traj, bits=bits)
    data = vbt.encode_bytes(traj, q)
    t_enc = time.perf_counter() - t0
    t0 = time.perf_counter()
    dec = vbt.decode_bytes(data)
    out = vbt_render.render(dec.trajectory, basis=basis, overrides={"bank.cache_dir": cache})
    t_dec = time.perf_counter() - t0
    qual = quality(x, out.signal, fs=fs, basis=basis, offset_db=out.offset_db)
    duration = x.size / fs
    return {
        "case": name,
        "fs": fs,
        "duration_s": duration,
        "bits": bits,
        "bytes": len(data),
        "records": dec.n_records,
        "bytes_per_s": len(data) / duration,
        "ratio_pcm16": 2 * x.size / len(data),
        "ratio_pcm8_2k8": duration * 2800 / len(data),
        "band_rms_db": qual.band_error_rms_db,
        "s1_floor_db": qual.s1_model_error_rms_db,
        "level_err_db": qual.level_error_db,
        "win_level_rms_db": qual.window_level_rms_db,
        "D": qual.dissimilarity,
        "nonstat_orig_db": qual.non_stationarity_original_db,
        "nonstat_dec_db": qual.non_stationarity_decoded_db,
        "offset_db": out.offset_db,
        "encode_x_realtime": duration / t_enc,
        "decode_x_realtime": duration / t_dec,
        "encode_ms": 1000 * t_enc,
        "decode_ms": 1000 * t_dec,
    }


COLUMNS = [
    ("case", "{:<32}"),
    ("fs", "{:>6.0f}"),
    ("bytes", "{:>6d}"),
    ("records", "{:>4d}"),
    ("bytes_per_s", "{:>6.1f}"),
    ("ratio_pcm16", "{:>7.0f}"),
    ("ratio_pcm8_2k8", "{:>6.0f}"),
    ("band_rms_db", "{:>6.2f}"),
    ("s1_floor_db", "{:>6.2f}"),
    ("level_err_db", "{:>+6.2f}"),
    ("D", "{:>6.2f}"),
    ("nonstat_orig_db", "{:>6.2f}"),
    ("nonstat_dec_db", "{:>6.2f}"),
    ("encode_ms", "{:>7.0f}"),
    ("decode_ms", "{:>7.0f}"),
]
HEADS = [
    "case",
    "fs",
    "bytes",
    "rec",
    "B/s",
    "x16bit",
    "x8@2k8",
    "band",
    "S1flr",
    "level",
    "D",
    "NSorig",
    "NSdec",
    "enc ms",
    "dec ms",
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer cases")
    parser.add_argument("--bits", type=int, default=8)
    args = parser.parse_args()
    basis = default_basis()
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        cases = list(synthetic_cases(basis, 2800.0))
        if not args.quick:
            cases.append(("stationary @48k", 48000.0, shaped(basis.mean_db + 10 * basis.v1, 48000.0, 10, -40, 9)))
        if HATT.exists():
            cases += list(hatt_cases(basis, 2800.0, 3 if args.quick else 6))
        else:
            print(f"(shared HaTT spectra not found at {HATT}: synthetic cases only)")
        for name, fs, x in cases:
            rows.append(run_case(name, fs, x, basis, args.bits, cache))
    widths = [len(fmt.format(rows[0][key])) for key, fmt in COLUMNS]
    print(" ".join(f"{h:>{w}}" if i else f"{h:<{w}}" for i, (h, w) in enumerate(zip(HEADS, widths))))
    for r in rows:
        print(" ".join(fmt.format(r[key]) for key, fmt in COLUMNS))
    print(
        "band = RMS band-spectrum error (dB, whole signal); S1flr = the S1 model's own shape error; "
        "level = intensity error (dB); D = |t1 orig - t1 decoded|; NS = non-stationarity (dB); "
        "decode includes the engine's bank build (first case) or cache load."
    )
    out = ROOT / "benchmarks" / "results" / "bench_codec.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"bits": args.bits, "basis": basis.id, "rows": rows}, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
