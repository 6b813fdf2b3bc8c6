"""Statistics of the peers benchmark's latency trials (benchmarks/bench_peers.py).

A latency trial waits for the target's next audio cycle, a wait uniform over one cycle
(2.67 ms at 48 kHz / 128), so a median needs hundreds of trials to be known to 0.1 ms: its
95 % interval is about +-1.96 x period / (2 sqrt(n)), +-0.48 ms for n = 30 (one standard error
+-0.24) and +-0.09 ms for n = 800. The intervals here are

* :func:`median_ci`: distribution-free (order statistics of a binomial(n, 1/2) count);
* :func:`paired_bootstrap`: the trials are taken in rounds (one trial of every system per
  round, in a random order), so rounds are resampled whole: load that hits one round hits
  every system in it alike, and the interval of a ratio or a difference of medians keeps that
  pairing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["median_ci", "paired_bootstrap", "round_matrix"]


def _binom_cdf(k: int, n: int) -> float:
    """P(B <= k) for B ~ binomial(n, 1/2)."""
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    log_half_n = -n * math.log(2.0)
    return sum(
        math.exp(math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) + log_half_n) for i in range(k + 1)
    )


def median_ci(values: Sequence[float], conf: float = 0.95) -> tuple[float, float, float]:
    """The median and its distribution-free confidence interval (order statistics).

    Parameters
    ----------
    values : sequence of float, shape (n,)
    conf : float
        Coverage of the interval (at least this much; order statistics give discrete levels).

    Returns
    -------
    median, low, high : float
        NaN when there are no values; the interval is the whole range when n is too small.
    """
    x = np.sort(np.asarray(values, dtype=float))
    n = x.size
    if n == 0:
        return math.nan, math.nan, math.nan
    med = float(np.median(x))
    # the largest j with P(B < j) <= (1 - conf) / 2: [x_(j), x_(n-j+1)] (1-based) covers the median
    alpha = (1.0 - conf) / 2.0
    j = 0
    while j + 1 <= n // 2 and _binom_cdf(j, n) <= alpha:
        j += 1
    if j == 0:
        return med, float(x[0]), float(x[-1])
    return med, float(x[j - 1]), float(x[n - j])


def round_matrix(trials: dict[str, list[dict]], key: str, rounds: int) -> tuple[list[str], np.ndarray]:
    """``(names, matrix)``: matrix[r, s] = trial value ``key`` of system s in round r (NaN: none).

    Parameters
    ----------
    trials : dict of str to list of dict
        Per system, its accepted trials, each with ``round`` (int) and ``key``.
    key : str
    rounds : int
    """
    names = list(trials)
    m = np.full((rounds, len(names)), np.nan)
    for s, name in enumerate(names):
        for t in trials[name]:
            m[int(t["round"]), s] = float(t[key])
    return names, m


def paired_bootstrap(
    matrix: np.ndarray,
    statistic: Callable[[np.ndarray], np.ndarray],
    *,
    resamples: int = 4000,
    seed: int = 0,
    conf: float = 0.95,
) -> tuple[float, float, float]:
    """A statistic of per-round values and its percentile bootstrap interval, rounds resampled whole.

    Parameters
    ----------
    matrix : ndarray, shape (rounds, systems)
        One value per round and system; NaN where a trial was rejected.
    statistic : callable
        ``statistic(m)`` with ``m`` of shape (batch, rounds, systems) returns shape (batch,).
    resamples : int
    seed : int
        Seed of the resampling (the result is reproducible).
    conf : float

    Returns
    -------
    value, low, high : float
        The statistic on the data as measured, and the interval.
    """
    rng = np.random.default_rng(seed)
    n = matrix.shape[0]
    value = float(statistic(matrix[None, :, :])[0])
    out = []
    batch = max(1, 2_000_000 // max(1, matrix.size))
    for start in range(0, resamples, batch):
        k = min(batch, resamples - start)
        idx = rng.integers(0, n, size=(k, n))
        out.append(statistic(matrix[idx]))
    boot = np.concatenate(out)
    boot = boot[np.isfinite(boot)]
    if not boot.size:
        return value, math.nan, math.nan
    lo, hi = np.percentile(boot, [100 * (1 - conf) / 2, 100 * (1 + conf) / 2])
    return value, float(lo), float(hi)
