"""Dissimilarity model: metric properties (property-style, seeded), weights, MDS, Procrustes."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.dissimilarity import (
    PAPER_WEIGHTS,
    classical_mds,
    dissimilarity,
    dissimilarity_matrix,
    local_distances,
    procrustes,
)
from vibsynth.errors import ParameterError


def _random_weights(rng: np.random.Generator) -> np.ndarray:
    w = rng.exponential(1.0, 8)
    w[rng.random(8) < 0.4] = 0.0  # sparse, like a Lasso fit
    return w


def test_paper_weights_use_only_the_first_component():
    assert PAPER_WEIGHTS.shape == (8,)
    assert PAPER_WEIGHTS[0] == 1.0 and not PAPER_WEIGHTS[1:].any()
    x = np.array([10.0, 5, 5, 5, 5, 5, 5, 5])
    y = np.array([4.0, -5, 9, 0, 1, 2, 3, 4])
    assert dissimilarity(x, y) == pytest.approx(6.0)


def test_hand_computed_value_and_short_weights():
    assert dissimilarity([10.0, 3.0], [4.0, -1.0], weights=[1.0, 0.5]) == pytest.approx(8.0)
    # A shorter weight vector weighs the first components only.
    assert dissimilarity([10.0, 3.0, 7.0], [4.0, -1.0, 0.0], weights=[1.0, 0.5]) == pytest.approx(8.0)


@pytest.mark.parametrize("trial", range(20))
def test_metric_properties(rng, trial):
    w = _random_weights(rng)
    x, y, z = rng.normal(0, 20, size=(3, 8))
    assert dissimilarity(x, x, w) == 0.0
    assert dissimilarity(x, y, w) == pytest.approx(dissimilarity(y, x, w), abs=1e-12)
    assert dissimilarity(x, y, w) >= 0.0
    assert dissimilarity(x, z, w) <= dissimilarity(x, y, w) + dissimilarity(y, z, w) + 1e-9


def test_vectorised_over_leading_axes(rng):
    w = _random_weights(rng)
    a = rng.normal(size=(5, 3, 8))
    b = rng.normal(size=(3, 8))
    out = dissimilarity(a, b, w)
    assert out.shape == (5, 3)
    assert out[4, 2] == pytest.approx(np.sum(w * np.abs(a[4, 2] - b[2])))
    assert local_distances(a, b).shape == (5, 3, 8)


def test_matrix_is_symmetric_with_zero_diagonal(rng):
    s = rng.normal(0, 10, size=(7, 8))
    d = dissimilarity_matrix(s, _random_weights(rng))
    assert d.shape == (7, 7)
    assert np.allclose(d, d.T) and np.all(np.diag(d) == 0)
    assert np.allclose(dissimilarity_matrix(s), np.abs(s[:, None, 0] - s[None, :, 0]))


@pytest.mark.parametrize(
    "weights, match",
    [([1.0, -0.1], "non-negative"), ([np.nan], "finite"), (np.ones(9), "9 weights"), (np.ones((2, 4)), "1-D")],
)
def test_bad_weights_are_rejected(weights, match):
    with pytest.raises(ParameterError, match=match):
        dissimilarity(np.zeros(8), np.ones(8), weights)


def test_bad_scores_are_rejected():
    with pytest.raises(ParameterError, match="NaN"):
        dissimilarity([np.nan] * 8, np.zeros(8))
    with pytest.raises(ParameterError, match="components"):
        dissimilarity(np.zeros(8), np.zeros(7))


def test_mds_recovers_a_known_configuration(rng):
    truth = rng.normal(0, 3, size=(12, 2)) * [3.0, 1.0]  # anisotropic: the first axis dominates
    d = np.linalg.norm(truth[:, None] - truth[None, :], axis=-1)
    coords, eig = classical_mds(d, 2, return_eigenvalues=True)
    assert coords.shape == (12, 2)
    # Distances are reproduced exactly, and the map equals the truth up to a rigid motion.
    assert np.allclose(np.linalg.norm(coords[:, None] - coords[None, :], axis=-1), d, atol=1e-8)
    aligned, rms = procrustes(truth, coords)
    assert rms < 1e-8
    assert eig[0] >= eig[1] > 1e-6 and np.all(np.abs(eig[2:]) < 1e-8)
    assert np.allclose(coords.mean(axis=0), 0, atol=1e-9)


def test_mds_one_dimension_orders_items_like_t1(rng):
    t1 = rng.normal(0, 20, 10)
    coords = classical_mds(dissimilarity_matrix(np.column_stack([t1, rng.normal(size=(10, 7))])), 1)
    assert abs(np.corrcoef(coords[:, 0], t1)[0, 1]) > 0.999


def test_mds_rejects_bad_matrices():
    with pytest.raises(ParameterError, match="square"):
        classical_mds(np.zeros((3, 4)))
    with pytest.raises(ParameterError, match="symmetric"):
        classical_mds(np.array([[0, 1.0, 2], [1, 0, 1], [3, 1, 0]]))
    with pytest.raises(ParameterError, match="n_components"):
        classical_mds(np.zeros((3, 3)), 3)


def test_procrustes_undoes_a_similarity_transform(rng):
    a = rng.normal(size=(9, 2))
    theta = 0.7
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    moved = 2.5 * a @ rot * [1, -1] + [3.0, -1.0]  # rotation, reflection, scale, shift
    aligned, rms = procrustes(a, moved)
    assert rms < 1e-10 and np.allclose(aligned, a)
