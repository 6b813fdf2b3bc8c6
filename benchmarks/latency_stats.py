"""Summary of latency samples shared by the latency benchmarks (studio, OSCQuery)."""

from __future__ import annotations

import numpy as np


def summary_ms(values_ms: list[float]) -> dict[str, float]:
    """``n``, median, p99, min and max of latencies in ms (rounded to µs)."""
    a = np.asarray(values_ms)
    return {
        "n": int(a.size),
        "median_ms": round(float(np.median(a)), 3),
        "p99_ms": round(float(np.percentile(a, 99)), 3),
        "min_ms": round(float(a.min()), 3),
        "max_ms": round(float(a.max()), 3),
    }
