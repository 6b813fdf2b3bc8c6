"""Curve simplification: the stated error is the real one, within tolerance when the budget allows, bounded points."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.simplify import simplify
from vibsynth.errors import ParameterError


def _polyline(t, knots_t, knots_v):
    return np.interp(t, knots_t, knots_v)


def test_a_noisy_polyline_comes_back_as_few_points_within_tolerance():
    rng = np.random.default_rng(11)
    t = np.linspace(0, 10, 2001)
    knots = np.array([0, 1.3, 2.0, 4.4, 7.1, 10])
    a = _polyline(t, knots, [0, 0.8, 0.2, 0.2, 0.9, 0.1]) + rng.uniform(-0.005, 0.005, t.size)
    b = _polyline(t, knots, [-1, 2, 2, -3, 0, 1]) + rng.uniform(-0.02, 0.02, t.size)
    y = np.stack([a, b], axis=1)
    result = simplify(t, y, [0.02, 0.08], max_points=500)
    assert result.within and result.index.size <= 14 and result.index[0] == 0 and result.index[-1] == t.size - 1
    fitted = np.stack([np.interp(t, t[result.index], y[result.index, c]) for c in range(2)], axis=1)
    assert np.allclose(np.max(np.abs(fitted - y), axis=0), result.max_error)
    assert np.all(result.max_error <= [0.02, 0.08])


def test_the_budget_bounds_the_points_and_the_error_says_so():
    rng = np.random.default_rng(2)
    t = np.arange(5000) * 0.01
    y = np.cumsum(rng.standard_normal(5000)) * 0.05  # a random walk needs many points
    full = simplify(t, y, 0.01, max_points=5000)
    short = simplify(t, y, 0.01, max_points=50)
    assert short.index.size == 50 and not short.within and short.max_error[0] > 0.01
    assert full.within and full.index.size > 50
    assert simplify(t, y, 0.5, max_points=5000).index.size < full.index.size  # looser -> fewer


def test_edges_and_bad_input():
    assert simplify([0.0], [[1.0, 2.0]], [0.1, 0.1], max_points=5).index.tolist() == [0]
    assert simplify([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], 0.01, max_points=5).index.tolist() == [0, 2]  # a line
    for args in (([0, 0, 1], [1, 2, 3], 0.1), ([0, 1], [1, np.nan], 0.1), ([0, 1], [1, 2], 0.0), ([0, 1], [1], 0.1)):
        with pytest.raises(ParameterError):
            simplify(*args, max_points=10)
