"""Simplify sampled curves to few breakpoints with a stated maximum error (Ramer-Douglas-Peucker).

A tracked trajectory has a value every few milliseconds; a clip holds at most a few thousand
keyframes and a person editing it wants far fewer. :func:`simplify` keeps the first and last
samples and repeatedly adds the sample farthest from the straight lines between the kept ones
(the Ramer-Douglas-Peucker split, always on the worst segment first), until every sample of
every curve is within its tolerance of the lines, or the point budget is spent.

The error is *vertical* (the value at each sample's time, which is what plays), measured per
curve in its own units and divided by that curve's tolerance; curves are simplified jointly
(one set of breakpoints for all of them: a clip keyframe carries intensity and balance
together). Splitting the worst segment first makes the result the best this greedy method
finds for any budget: stopping early leaves the largest errors spread evenly.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.errors import ParameterError

__all__ = ["Simplified", "simplify"]


@dataclass(frozen=True)
class Simplified:
    """What :func:`simplify` kept.

    Attributes
    ----------
    index : ndarray, int64, shape (m,)
        Kept samples, increasing; the first and the last sample are always kept.
    max_error : ndarray, float64, shape (k,)
        Largest distance of any sample of each curve from the simplified curve (its units).
    within : bool
        Every curve is within its tolerance (False when the budget ran out first).
    """

    index: NDArray[np.int64]
    max_error: NDArray[np.float64]
    within: bool


def _segment_error(
    t: NDArray[np.float64], y: NDArray[np.float64], scale: NDArray[np.float64], a: int, b: int
) -> tuple[float, int]:
    """The worst scaled vertical error strictly between samples ``a`` and ``b``, and where it is."""
    if b - a < 2:
        return 0.0, -1
    inner = slice(a + 1, b)
    u = (t[inner] - t[a]) / (t[b] - t[a])
    line = y[a] + u[:, None] * (y[b] - y[a])
    err = np.max(np.abs(y[inner] - line) * scale, axis=1)
    k = int(np.argmax(err))
    return float(err[k]), a + 1 + k


def simplify(times: ArrayLike, values: ArrayLike, tolerance: ArrayLike, *, max_points: int) -> Simplified:
    """Breakpoints of a piecewise-linear curve within ``tolerance`` of ``values`` (at most ``max_points``).

    Parameters
    ----------
    times : array_like, shape (n,)
        Strictly increasing sample times.
    values : array_like, shape (n,) or (n, k)
        One curve per column.
    tolerance : float or array_like, shape (k,)
        Largest vertical error allowed per curve (> 0).
    max_points : int
        Most breakpoints kept (>= 2, or 1 for a single sample).

    Returns
    -------
    result : Simplified

    Raises
    ------
    ParameterError
        Shapes that do not match, times not increasing, non-finite values, a tolerance <= 0.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    y = np.asarray(values, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    if y.ndim != 2 or y.shape[0] != t.size or t.size == 0:
        raise ParameterError(f"times (n,) and values (n, k) must match, got {t.shape} and {np.shape(values)}")
    tol = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (y.shape[1],))
    if not np.all(tol > 0) or not np.all(np.isfinite(tol)):
        raise ParameterError(f"tolerances must be positive, got {tol.tolist()}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ParameterError("times and values must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ParameterError("times must strictly increase")
    if t.size == 1:
        return Simplified(np.zeros(1, np.int64), np.zeros(y.shape[1]), True)
    if max_points < 2:
        raise ParameterError(f"max_points must be at least 2, got {max_points}")
    scale = 1.0 / tol
    n = t.size
    kept = [0, n - 1]
    heap: list[tuple[float, int, int, int]] = []
    err, at = _segment_error(t, y, scale, 0, n - 1)
    if at >= 0:
        heap.append((-err, 0, n - 1, at))
    while heap and len(kept) < max_points and -heap[0][0] > 1.0:
        _, a, b, at = heapq.heappop(heap)
        kept.append(at)
        for lo, hi in ((a, at), (at, b)):
            err, where = _segment_error(t, y, scale, lo, hi)
            if where >= 0:
                heapq.heappush(heap, (-err, lo, hi, where))
    index = np.array(sorted(kept), dtype=np.int64)
    fitted = np.empty_like(y)
    for c in range(y.shape[1]):
        fitted[:, c] = np.interp(t, t[index], y[index, c])
    max_error = np.max(np.abs(fitted - y), axis=0)
    return Simplified(index, max_error, bool(np.all(max_error <= tol * (1 + 1e-9))))
