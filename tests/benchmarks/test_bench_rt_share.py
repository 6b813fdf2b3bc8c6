"""The real-time share benchmark's summary (benchmarks/bench_rt_share.py): per-10 s medians, maxima, totals."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_rt_share import summarise  # noqa: E402


def test_windows_of_any_length_are_summarised_per_10_seconds(rng):
    seconds = rng.uniform(4.0, 12.0, 7)
    late = rng.integers(0, 9, 7)
    windows = [
        {"seconds": float(s), "xrun_callbacks": int(k) + 1, "target_late_cycles": int(k), "cpu_pct": 3.0,
         "machine_busy_pct_of_all_cores": 50.0}
        for s, k in zip(seconds, late)
    ]  # fmt: skip
    out = summarise(windows, 10.0)
    per10 = 10.0 * late / seconds
    assert out["windows"] == 7
    assert out["target_late_cycles"]["median_per_10s"] == pytest.approx(np.median(per10))
    assert out["target_late_cycles"]["max_per_10s"] == pytest.approx(per10.max())
    assert out["target_late_cycles"]["total"] == late.sum()
    assert out["xrun_callbacks"]["total"] == late.sum() + 7
    assert "status_underflows" not in out  # a figure no window has is left out, not zero


def test_a_figure_some_windows_lack_is_summarised_over_the_others():
    windows = [
        {"seconds": 5.0, "xrun_callbacks": 2, "status_underflows": None, "machine_busy_pct_of_all_cores": 1.0},
        {"seconds": 10.0, "xrun_callbacks": 2, "status_underflows": 4, "machine_busy_pct_of_all_cores": 1.0},
    ]
    out = summarise(windows, 10.0)
    # paired with its own window's length (10 s), not the first window's
    assert out["status_underflows"]["values"] == [4] and out["status_underflows"]["max_per_10s"] == 4.0
    assert out["xrun_callbacks"]["max_per_10s"] == 4.0  # 2 in 5 s
