#!/usr/bin/env python3
"""DSP benchmark: exact vs iterative synthesis (time, max band error); analysis throughput.

    python benchmarks/bench_dsp.py [--repeats 5] [--json benchmarks/results/dsp.json]

Prints a table and writes JSON. Times are medians over repeats (wall clock, one thread).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.dsp.analysis import analyze  # noqa: E402
from vibsynth.dsp.filterbank import band_powers  # noqa: E402
from vibsynth.dsp.synthesis import synthesize, synthesize_iterative  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402


def _median_time(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "dsp.json")
    args = parser.parse_args()
    basis = default_basis()
    target = basis.spectrum_for_balance(0.7)
    rows = []
    for fs in (2800.0, 48000.0):
        for seconds in (1.0, 4.0):
            n = int(fs * seconds)
            for method, fn in (("exact", synthesize), ("iterative", synthesize_iterative)):
                rng = np.random.default_rng(1)
                t, res = _median_time(lambda: fn(target, fs=fs, n_samples=n, level_db=-50.0, rng=rng), args.repeats)
                measured = 10 * np.log10(band_powers(res.signal, fs=fs))
                diff = measured - target
                err = float(np.max(np.abs(diff - diff.mean())))
                rows.append(
                    {
                        "method": method,
                        "fs_hz": fs,
                        "seconds": seconds,
                        "time_s": t,
                        "max_band_error_db": err,
                        "iterations": res.iterations,
                    }
                )
    analysis_rows = []
    for fs in (2800.0, 48000.0):
        seconds = 10.0
        x = synthesize(target, fs=fs, n_samples=int(fs * seconds), level_db=-50.0, rng=np.random.default_rng(2)).signal
        t, _ = _median_time(lambda: analyze(x, fs=fs, basis=basis), args.repeats)
        analysis_rows.append({"fs_hz": fs, "seconds": seconds, "time_s": t, "x_real_time": seconds / t})

    print(
        f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
        f"median of {args.repeats}"
    )
    print(f"{'method':<10} {'rate Hz':>8} {'len s':>6} {'time ms':>9} {'iters':>6} {'max band err dB':>16}")
    for r in rows:
        print(
            f"{r['method']:<10} {r['fs_hz']:8.0f} {r['seconds']:6.1f} {1e3 * r['time_s']:9.1f} "
            f"{r['iterations']:6d} {r['max_band_error_db']:16.2e}"
        )
    print(f"\n{'analysis':<10} {'rate Hz':>8} {'len s':>6} {'time ms':>9} {'x real time':>12}")
    for r in analysis_rows:
        print(
            f"{'analyze':<10} {r['fs_hz']:8.0f} {r['seconds']:6.1f} {1e3 * r['time_s']:9.1f} {r['x_real_time']:12.0f}"
        )
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(
        json.dumps(
            {"synthesis": rows, "analysis": analysis_rows, "machine": platform.platform(), "repeats": args.repeats},
            indent=2,
        )
    )
    print(f"\nJSON: {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
