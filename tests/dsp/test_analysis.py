"""Analysis of recordings and the paper's experiment-3 variants."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.analysis import MIN_DURATION_S, analyze, check_variant, variant_spectra
from vibsynth.dsp.synthesis import synthesize
from vibsynth.errors import ParameterError


@pytest.fixture
def recording(basis, rng):
    """A texture-like recording: a database-like spectrum with all 8 components active."""
    scores = rng.uniform(-1.5, 1.5, basis.n_components) * basis.score_std
    target = basis.reconstruct(scores)
    fs = 2800.0
    return synthesize(target, fs=fs, n_samples=int(2 * fs), level_db=-35.0, rng=rng).signal, fs


def test_analysis_reports_every_attribute(basis, recording):
    x, fs = recording
    a = analyze(x, fs=fs, basis=basis)
    assert a.scores.shape == (8,) and a.band_db.shape == (30,)
    assert a.level_db == pytest.approx(-35.0, abs=0.01)
    assert a.t1 == pytest.approx(a.scores[0])
    assert a.balance == pytest.approx(float(basis.balance_from_t1(a.t1)))
    assert a.duration_s == pytest.approx(2.0)
    assert a.non_stationarity_db < 2.0
    assert not a.outside_database
    assert set(a.to_dict()) >= {"level_db", "balance", "t1", "scores", "band_db", "non_stationarity_db"}


@pytest.mark.parametrize("fs", [2800.0, 48000.0])
def test_variants_keep_t1_and_intensity(basis, recording, fs, rng):
    x, rec_fs = recording
    a = analyze(x, fs=rec_fs, basis=basis)
    spectra = variant_spectra(a, basis)
    assert set(spectra) == {"S1", "S1:8", "S2:8", "M"}
    out = {}
    for name, target in spectra.items():
        y = synthesize(target, fs=fs, n_samples=int(fs), level_db=a.level_db, rng=rng).signal
        out[name] = analyze(y, fs=fs, basis=basis)
        assert out[name].level_db == pytest.approx(a.level_db, abs=0.1)
    assert out["S1"].t1 == pytest.approx(a.t1, abs=0.05)
    assert np.allclose(out["S1:8"].scores, a.scores, atol=0.05)
    assert out["S2:8"].t1 == pytest.approx(0.0, abs=0.05)
    assert np.allclose(out["S2:8"].scores[1:], a.scores[1:], atol=0.05)
    assert np.allclose(out["M"].scores, 0.0, atol=0.05)


def test_outside_database_is_flagged_not_clamped(basis, rng):
    fs = 4000.0
    t1 = basis.t1_min * 1.5
    x = synthesize(basis.mean_db + t1 * basis.v1, fs=fs, n_samples=int(fs), level_db=-40, rng=rng).signal
    a = analyze(x, fs=fs, basis=basis)
    assert a.outside_database
    assert a.t1 == pytest.approx(t1, abs=0.05)
    assert a.balance < -1.0


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda fs: np.zeros(int(fs)), "silent"),
        (lambda fs: np.ones(int(fs)), "silent"),
        (lambda fs: np.random.default_rng(0).standard_normal(int(fs * MIN_DURATION_S / 2)), "too short"),
    ],
)
def test_unanalysable_signals_are_rejected(basis, make, message):
    with pytest.raises(ParameterError, match=message):
        analyze(make(4000.0), fs=4000.0, basis=basis)


def test_unknown_variant_is_rejected():
    with pytest.raises(ParameterError, match="S1:8"):
        check_variant("S3")
