"""Basis: PCA properties, normalisation idempotence, balance units, serialisation, the shipped default."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.basis import Basis, fit_basis, normalise_db
from vibsynth.errors import ParameterError


def test_components_are_orthonormal_and_orthogonal_to_level(basis):
    V = basis.components
    assert np.allclose(V @ V.T, np.eye(basis.n_components), atol=1e-6)
    assert np.allclose(V.sum(axis=1), 0.0, atol=1e-6)
    assert abs(basis.mean_db.mean()) < 1e-6


def test_normalisation_is_idempotent_so_t_is_recovered_exactly(basis, rng):
    for t in rng.uniform(-100, 100, 20):
        spectrum = basis.mean_db + t * basis.v1 + rng.uniform(-80, 20)  # any level
        assert basis.scores(spectrum)[0] == pytest.approx(t, abs=1e-6)
        assert np.allclose(normalise_db(normalise_db(spectrum)), normalise_db(spectrum))


def test_v1_is_a_low_high_tilt_with_positive_meaning_brighter(basis):
    v1 = basis.v1
    log_f = np.log(basis.centres_hz)
    assert np.corrcoef(v1, log_f)[0, 1] > 0.9
    third = basis.n_bands // 3
    assert v1[:third].max() < 0 < v1[-third:].min()


def test_default_basis_explains_most_variance_with_v1(basis):
    evr = basis.explained_variance_ratio
    assert evr[0] > 0.5 and np.all(np.diff(evr) <= 0) and evr.sum() > 0.95


def test_balance_units(basis):
    pct = basis.t1_percentiles
    assert basis.balance_from_t1(pct[98.0]) == pytest.approx(1.0)
    assert basis.balance_from_t1(pct[2.0]) == pytest.approx(-1.0)
    assert basis.balance_from_t1(0.0) == 0.0
    for b in np.linspace(-4, 4, 33):
        assert basis.balance_from_t1(basis.t1_from_balance(b)) == pytest.approx(b)
    with pytest.raises(ParameterError):
        basis.t1_from_balance(float("nan"))


def test_fit_recovers_a_planted_tilt(rng):
    centres = np.geomspace(10, 1000, 30)
    tilt = np.log(centres) - np.log(centres).mean()
    tilt /= np.linalg.norm(tilt)
    spectra = (
        5.0 * rng.standard_normal((200, 1)) * tilt
        + 0.3 * rng.standard_normal((200, 30))
        + rng.uniform(-50, 0, (200, 1))
    )
    fitted = fit_basis(spectra, centres=centres)
    assert abs(fitted.v1 @ tilt) > 0.99
    assert fitted.v1 @ tilt > 0  # sign convention: brighter = positive


def test_dict_round_trip_keeps_the_id_and_numbers(basis):
    again = Basis.from_dict(basis.to_dict())
    assert again.id == basis.id
    assert np.allclose(again.components, basis.components, atol=1e-8)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("mean_db"), "missing the key 'mean_db'"),
        (lambda d: d.__setitem__("mean_db", d["mean_db"][:5]), "mean_db must have 30"),
        (lambda d: d["components"][0].__setitem__(0, float("nan")), "NaN"),
        (lambda d: d.__setitem__("components", [[1.0] * 30] * 8), "orthonormal"),
        (lambda d: d.__setitem__("format", 99), "format 99"),
    ],
)
def test_invalid_basis_data_is_rejected(basis, mutate, message):
    data = basis.to_dict()
    mutate(data)
    with pytest.raises(ParameterError, match=message):
        Basis.from_dict(data)
