"""Research tools: ratings reader, the paper's Lasso fit on simulated ratings, MDS map, missing sklearn."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from vibsynth.dsp.dissimilarity import local_distances
from vibsynth.errors import InputError, VibsynthError
from vibsynth.research.dissim import (
    MissingDependencyError,
    fit_dissimilarity_weights,
    fit_from_ratings,
    mds_map,
    read_ratings,
)

SCORE_SD = np.array([21.2, 8.7, 4.6, 3.0, 1.9, 1.6, 1.06, 0.83])  # default basis spread


def simulate(rng, weights, *, n_items=18, noise=0.05, intercept=0.12):
    scores = rng.normal(size=(n_items, 8)) * SCORE_SD
    i, j = np.triu_indices(n_items)  # 171 pairs, self-pairs included, as in the paper
    d = local_distances(scores[i], scores[j])
    signal = d @ weights
    ratings = intercept + signal + rng.normal(0, noise, signal.size)
    ceiling = signal.var() / (signal.var() + noise**2)
    return scores, d, ratings, ceiling


def test_fit_recovers_first_component_weights(rng):
    w = np.array([0.012, 0, 0, 0, 0, 0, 0, 0])
    _, d, y, ceiling = simulate(rng, w)
    fit = fit_dissimilarity_weights(d, y, n_splits=10, seed=1)
    assert fit.weights[0] == pytest.approx(0.012, rel=0.1)
    assert np.all(fit.weights[1:] < 0.1 * fit.weights[0])
    assert fit.intercept == pytest.approx(0.12, abs=0.05)
    assert ceiling - 0.1 < fit.r2_mean <= ceiling + 0.05
    assert fit.r2_single_mean[0] > ceiling - 0.1 and np.all(fit.r2_single_mean[1:] < 0.3)
    assert np.all(np.abs(fit.r2_first_mean - fit.r2_first_mean[0]) < 0.05)  # Fig. 6b: flat blue curve
    assert fit.selected_fraction[0] == 1.0
    assert fit.n_train + fit.n_test == 171 and fit.n_test == 34


def test_fit_recovers_two_components_and_is_reproducible(rng):
    w = np.array([0.008, 0.0, 0.03, 0, 0, 0, 0, 0])
    _, d, y, ceiling = simulate(rng, w, noise=0.04)
    a = fit_dissimilarity_weights(d, y, n_splits=5, seed=3, components=False)
    b = fit_dissimilarity_weights(d, y, n_splits=5, seed=3, components=False)
    assert np.array_equal(a.r2_splits, b.r2_splits)
    assert a.weights[0] == pytest.approx(0.008, rel=0.15) and a.weights[2] == pytest.approx(0.03, rel=0.15)
    assert a.r2_mean > ceiling - 0.1
    cd = fit_dissimilarity_weights(d, y, n_splits=2, seed=3, components=False, solver="cd")
    assert np.allclose(cd.weights, a.weights, atol=0.003)


def test_pure_noise_ratings_give_no_predictive_power(rng):
    _, d, _, _ = simulate(rng, np.zeros(8))
    y = rng.normal(0.5, 0.1, d.shape[0])
    fit = fit_dissimilarity_weights(d, y, n_splits=5, seed=0, components=False)
    assert fit.r2_mean < 0.1


def test_fit_validates_input():
    with pytest.raises(VibsynthError, match="too few"):
        fit_dissimilarity_weights(np.ones((10, 8)), np.arange(10.0))
    with pytest.raises(VibsynthError, match="shape|n_pairs"):
        fit_dissimilarity_weights(np.ones((30, 8)), np.ones(29))


def test_missing_sklearn_message(monkeypatch):
    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "sklearn" or name.startswith("sklearn."):
            raise ImportError("No module named 'sklearn'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(MissingDependencyError, match=r"needs scikit-learn: pip install 'vibsynth\[research\]'"):
        fit_dissimilarity_weights(np.ones((40, 8)), np.arange(40.0))


def write_ratings(tmp_path, rows, header="file_a,file_b,rating"):
    for name in {r[0] for r in rows} | {r[1] for r in rows}:
        (tmp_path / name).write_bytes(b"")
    text = (header + "\n" if header else "") + "\n".join(f"{a},{b},{r}" for a, b, r in rows) + "\n"
    path = tmp_path / "ratings.csv"
    path.write_text(text)
    return path


def test_read_ratings_averages_repeated_pairs(tmp_path):
    path = write_ratings(
        tmp_path,
        [
            ("a.wav", "b.wav", 0.2),
            ("b.wav", "a.wav", 0.4),
            ("a.wav", "c.wav", 0.9),
            ("b.wav", "c.wav", 0.5),
            ("a.wav", "a.wav", 0.1),
        ],
    )
    t = read_ratings(path)
    assert t.names == ["a", "b", "c"] and t.n_rows == 5
    lookup = {tuple(p): (r, c) for p, r, c in zip(t.pairs.tolist(), t.ratings, t.counts)}
    assert lookup[(0, 1)] == (pytest.approx(0.3), 2) and lookup[(0, 0)][0] == pytest.approx(0.1)
    m = t.matrix()
    assert m[0, 1] == m[1, 0] == pytest.approx(0.3) and m[0, 0] == 0


def test_read_ratings_errors_name_the_line(tmp_path):
    path = write_ratings(tmp_path, [("a.wav", "b.wav", 0.2), ("a.wav", "c.wav", "high")])
    with pytest.raises(InputError, match=r"ratings.csv:3: rating 'high' is not a number"):
        read_ratings(path)
    path.write_text("file_a,file_b,rating\na.wav,b.wav,0.1\na.wav,missing.wav,0.3\n")
    with pytest.raises(InputError, match=r":3: recording 'missing.wav' not found"):
        read_ratings(path)
    path.write_text("a.wav,b.wav\n")
    with pytest.raises(InputError, match=r":1: expected file_a,file_b,rating"):
        read_ratings(path)
    path.write_text("a.wav,b.wav,0.1\nb.wav,c.wav,0.2\n")  # no header, 3 files: fine
    assert read_ratings(path).n_rows == 2
    path.write_text("a.wav,b.wav,0.1\nb.wav,c.wav,0.2\n")
    t = read_ratings(path)
    with pytest.raises(InputError, match="never rated"):
        t.matrix()


def test_mds_map_first_axis_follows_t1(rng, tmp_path):
    scores, d, y, _ = simulate(rng, np.array([0.012, 0, 0, 0, 0, 0, 0, 0]), n_items=10, noise=0.02)
    n = 10
    i, j = np.triu_indices(n)
    rows = [(f"s{a}.wav", f"s{b}.wav", float(r)) for a, b, r in zip(i, j, y)]
    table = read_ratings(write_ratings(tmp_path, rows))
    order = [int(f.stem[1:]) for f in table.files]
    m = mds_map(table, scores[order])
    assert m.rated.shape == (n, 2) and m.predicted.shape == (n, 2)
    assert m.component_r[0, 0] > 0.9  # the paper: r = 0.94 between V1 and MDS dimension 1
    fit = fit_from_ratings(table, scores[order], n_splits=3, seed=0, cv=5, components=False)
    assert fit.weights[0] > 0


def test_a_component_that_only_holds_rounding_noise_gets_no_weight(rng):
    """Stimuli made as M + t1 V1 have T2..T8 equal up to rounding; noise must not take a (huge) weight."""
    t1 = rng.uniform(-30, 30, 8)
    scores = np.zeros((8, 8))
    scores[:, 0] = t1
    scores[:, 1:] = rng.standard_normal((8, 7)) * 1e-9
    pairs = np.array([(i, j) for i in range(8) for j in range(i, 8)])
    d = np.abs(scores[pairs[:, 0]] - scores[pairs[:, 1]])
    ratings = d[:, 0] / 60.0 + rng.normal(0, 0.01, len(pairs))
    fit = fit_dissimilarity_weights(d, ratings, n_splits=5, cv=5, seed=1)
    assert fit.weights[0] == pytest.approx(1 / 60, rel=0.2)
    assert np.all(fit.weights[1:] == 0.0)
