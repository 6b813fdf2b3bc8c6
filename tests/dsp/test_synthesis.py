"""Exact synthesis: band powers, intensity, loops, balance round trip; and the iterative reference."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.analysis import analyze
from vibsynth.dsp.filterbank import band_powers
from vibsynth.dsp.intensity import intensity_level_db, knob_to_level_db
from vibsynth.dsp.synthesis import SpectralShaper, synthesize, synthesize_iterative
from vibsynth.errors import ParameterError

RATES = (2800.0, 8000.0, 44100.0, 48000.0)


def _realistic_targets(basis, rng, n):
    """Spectra like the database's: M + scores drawn within 2 std of each component."""
    scores = rng.uniform(-2, 2, size=(n, basis.n_components)) * basis.score_std
    return basis.reconstruct(scores)


@pytest.mark.parametrize("fs", RATES)
def test_measured_band_powers_equal_the_target_within_0_1_db(basis, rng, fs):
    for target in _realistic_targets(basis, rng, 4):
        level = rng.uniform(-70, -30)
        result = synthesize(target, fs=fs, n_samples=int(fs), level_db=level, rng=rng)
        measured = 10 * np.log10(band_powers(result.signal, fs=fs))
        diff = measured - target
        assert np.max(np.abs(diff - diff.mean())) <= 0.1
        assert intensity_level_db(result.signal, fs=fs) == pytest.approx(level, abs=0.1)
        assert result.max_band_error_db <= 0.1


def test_absolute_band_powers_without_a_level(basis, rng):
    target = basis.mean_db - 60.0
    result = synthesize(target, fs=8000.0, n_samples=8000, rng=rng)
    assert np.max(np.abs(10 * np.log10(band_powers(result.signal, fs=8000.0)) - target)) <= 0.1


def test_output_is_a_seamless_loop(basis, rng):
    fs = 8000.0
    result = synthesize(basis.mean_db, fs=fs, n_samples=8000, level_db=-40, rng=rng)
    x = result.signal
    twice = np.concatenate([x, x])
    # the jump across the seam is no larger than the signal's ordinary sample-to-sample steps
    steps = np.abs(np.diff(twice))
    assert steps[x.size - 1] <= np.percentile(steps, 99.9)
    # and band powers of a window straddling the seam equal those of the loop
    straddle = twice[x.size // 2 : x.size // 2 + x.size]
    assert np.allclose(band_powers(straddle, fs=fs), band_powers(x, fs=fs), rtol=1e-9)


@pytest.mark.parametrize("fs", RATES)
def test_round_trip_balance_and_intensity(basis, fs):
    rng = np.random.default_rng(7)
    shaper = SpectralShaper(fs=fs, n_samples=int(fs))
    phases = shaper.random_phases(rng)
    (_, low_t1), (_, high_t1) = shaper.reachable_t1(basis)
    high = float(basis.balance_from_t1(high_t1))
    for balance in np.linspace(-3.0, 3.0, 25):
        for knob in (0.2, 0.6, 1.0):
            level = knob_to_level_db(knob)
            x = shaper.render(shaper.power_envelope(shaper.solve_balance(basis, balance, level_db=level)), phases)
            a = analyze(x, fs=fs, basis=basis)
            assert a.level_db == pytest.approx(level, abs=0.2)
            if balance <= high:
                assert a.balance == pytest.approx(balance, abs=0.02), (balance, knob)
            else:  # beyond what the filter bank can measure: saturates at the reachable edge
                assert a.balance == pytest.approx(high, abs=0.02)


def test_reachable_range_covers_real_recordings(basis):
    """Recordings of other databases reach -3.3; the bank's grid spans +-3.5."""
    shaper = SpectralShaper(fs=8000.0, n_samples=8000)
    (_, low_t1), (_, high_t1) = shaper.reachable_t1(basis)
    assert basis.balance_from_t1(low_t1) < -3.5
    assert basis.balance_from_t1(high_t1) > 2.5
    assert basis.balance_from_t1(basis.t1_max) < basis.balance_from_t1(high_t1)  # all the database is reachable


def test_measured_balance_is_monotonic_in_the_requested_balance(basis):
    shaper = SpectralShaper(fs=4000.0, n_samples=4000)
    measured = [
        float(
            basis.balance_from_t1(basis.scores(shaper.weights_band_db(shaper.solve_balance(basis, b, level_db=-40)))[0])
        )
        for b in np.linspace(-6, 6, 97)
    ]
    assert np.all(np.diff(measured) >= -1e-9)


def test_iso_intensity_across_a_balance_sweep(basis):
    fs = 8000.0
    shaper = SpectralShaper(fs=fs, n_samples=8000)
    phases = shaper.random_phases(np.random.default_rng(3))
    levels = []
    for balance in np.linspace(-3.5, 3.5, 29):
        x = shaper.render(shaper.power_envelope(shaper.solve_balance(basis, balance, level_db=-50)), phases)
        levels.append(intensity_level_db(x, fs=fs))
    assert np.ptp(levels) <= 0.2


@pytest.mark.parametrize("fs", [2800.0, 8000.0])
def test_iterative_reference_converges(basis, rng, fs):
    target = _realistic_targets(basis, rng, 1)[0]
    result = synthesize_iterative(target, fs=fs, n_samples=int(fs), level_db=-40, rng=rng)
    assert result.max_band_error_db <= 0.1
    assert result.iterations > 1
    assert result.level_db == pytest.approx(-40, abs=1e-6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"band_db": np.zeros(29)}, "30 bands"),
        ({"band_db": np.full(30, np.nan)}, "NaN"),
        ({"band_db": np.zeros(30), "level_db": float("inf")}, "finite"),
        ({"band_db": np.zeros(30), "fs": 1000.0}, "too low"),
    ],
)
def test_bad_targets_are_rejected(kwargs, message):
    args = {"fs": 8000.0, "n_samples": 8000, **kwargs}
    with pytest.raises(ParameterError, match=message):
        synthesize(**args)
