"""Spatial textures: roll-off laws, phantom panning, and the perceptual mixing rule against the DSP core."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibsynth.dsp.analysis import analyze
from vibsynth.dsp.spatial import (
    ROLLOFFS,
    PhantomPanner,
    SpatialLayout,
    TextureSpectra,
    check_rolloff,
    distances,
    mix_sources,
    rolloff_weights,
)
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import ParameterError

GRID_4X4 = [(0.05 * i, 0.05 * j, 0.0) for j in range(4) for i in range(4)]


@pytest.fixture(scope="module")
def spectra(basis):
    return TextureSpectra(basis)


# --------------------------------------------------------------------------- roll-off laws
def test_each_law_follows_its_formula(rng):
    r = float(rng.uniform(0.01, 0.5))
    d = rng.uniform(0.0, 3.0 * r, 200)
    x = d / r
    assert np.allclose(rolloff_weights("linear", d, r), np.maximum(0.0, 1.0 - x))
    assert np.allclose(rolloff_weights("smooth", d, r), np.where(x < 1, 0.5 * (1 + np.cos(np.pi * x)), 0.0))
    assert np.allclose(rolloff_weights("inverse-square", d, r), 1.0 / (1.0 + x**2))


@pytest.mark.parametrize("law", ["linear", "smooth", "inverse-square"])
def test_distance_laws_are_one_at_the_source_and_fall_with_distance(law, rng):
    r = float(rng.uniform(0.01, 1.0))
    d = np.sort(rng.uniform(0.0, 5.0 * r, 500))
    w = rolloff_weights(law, np.concatenate([[0.0], d]), r)
    assert w[0] == 1.0
    assert np.all((w >= 0) & (w <= 1))
    assert np.all(np.diff(w) <= 1e-15)


def test_landmarks_of_the_laws():
    r = 0.2
    assert rolloff_weights("linear", [0.1, 0.2, 0.3], r) == pytest.approx([0.5, 0.0, 0.0])
    assert rolloff_weights("smooth", [0.1, 0.2, 0.3], r) == pytest.approx([0.5, 0.0, 0.0], abs=1e-15)
    # inverse-square: half power at the radius, never zero
    w = rolloff_weights("inverse-square", [0.2, 2.0, 200.0], r)
    assert w[0] == pytest.approx(0.5) and np.all(w > 0)


@pytest.mark.parametrize("radius", [0.0, -1.0, math.nan, math.inf])
def test_a_radius_must_be_finite_and_positive(radius):
    with pytest.raises(ParameterError, match="radius"):
        rolloff_weights("linear", [0.1], radius)


def test_unknown_law_names_the_choices():
    with pytest.raises(ParameterError, match="linear, smooth, inverse-square, phantom"):
        check_rolloff("cubic")
    with pytest.raises(ParameterError, match="not a law of the distance"):
        rolloff_weights("phantom", [0.1], 0.1)
    assert [check_rolloff(n) for n in ROLLOFFS] == list(ROLLOFFS)


def test_distances_accept_2d_and_3d_positions():
    assert distances([[0, 0], [0.3, 0.4]], [0, 0]) == pytest.approx([0.0, 0.5])
    assert distances([[0, 0, 0], [0, 0, 1]], [0, 0]) == pytest.approx([0.0, 1.0])
    with pytest.raises(ParameterError, match="finite"):
        distances([[0, 0, 0]], [math.nan, 0, 0])


# --------------------------------------------------------------------------- phantom
def _check_energy(w):
    assert np.all(w >= 0)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.count_nonzero(w > 1e-12) <= 3


def test_phantom_weights_sum_to_one_on_two_or_three_actuators(rng):
    for _ in range(20):
        layout = rng.uniform(-0.2, 0.2, (int(rng.integers(3, 17)), 3))
        layout[:, 2] *= 0.1  # actuators on a body surface: roughly a plane
        panner = PhantomPanner(layout)
        for point in rng.uniform(-0.4, 0.4, (50, 3)):
            _check_energy(panner.weights(point))


def test_phantom_between_two_actuators_is_the_tactile_brush_energy_model(rng):
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.1, 0.0, 0.0])
    panner = PhantomPanner([a, b, [0.2, 0.0, 0.0], [0.3, 0.0, 0.0]])  # a line of 4
    for beta in rng.uniform(0, 1, 20):
        w = panner.weights(a + beta * (b - a))
        # amplitudes sqrt(1 - beta) and sqrt(beta): squared, they add up to the source's
        assert w[:2] == pytest.approx([1 - beta, beta], abs=1e-12)
        assert w[2:] == pytest.approx([0.0, 0.0])


def test_phantom_inside_a_triangle_is_barycentric(rng):
    panner = PhantomPanner(GRID_4X4)
    points = np.asarray(GRID_4X4)
    for q in rng.uniform(0.0, 0.15, (50, 2)):
        w = panner.weights([q[0], q[1], 0.0])
        _check_energy(w)
        # the energy centroid of the actuators is the source position
        assert w @ points[:, :2] == pytest.approx(q, abs=1e-12)


def test_phantom_on_an_actuator_plays_only_it():
    panner = PhantomPanner(GRID_4X4)
    for i, p in enumerate(GRID_4X4):
        w = panner.weights(p)
        assert w[i] == pytest.approx(1.0) and w.sum() == pytest.approx(1.0)


def test_phantom_outside_the_layout_pans_along_the_nearest_edge():
    panner = PhantomPanner(GRID_4X4)
    w = panner.weights([0.075, -0.3, 0.0])  # below the bottom edge, between actuators 1 and 2 (0-based)
    assert w[1] == pytest.approx(0.5) and w[2] == pytest.approx(0.5)
    w = panner.weights([-1.0, -1.0, 0.0])  # beyond a corner: the corner alone
    assert w[0] == pytest.approx(1.0)


def test_phantom_is_continuous_along_a_path(rng):
    panner = PhantomPanner(GRID_4X4)
    start, stop = rng.uniform(-0.05, 0.2, 2), rng.uniform(-0.05, 0.2, 2)
    path = np.linspace(start, stop, 4001)
    w = np.stack([panner.weights([x, y, 0.0]) for x, y in path])
    step = np.linalg.norm(stop - start) / 4000
    # barycentric weights change at most (distance moved / smallest triangle height) per step
    assert np.abs(np.diff(w, axis=0)).max() <= 2 * step / 0.035 + 1e-9


def test_phantom_on_degenerate_layouts():
    assert PhantomPanner([[0.1, 0.2, 0.0]]).weights([5, 5, 5]) == pytest.approx([1.0])
    assert PhantomPanner([[0, 0, 0], [0, 0, 0]]).weights([1, 0, 0]) == pytest.approx([0.5, 0.5])
    line = PhantomPanner([[0, 0, 0], [0, 0.1, 0], [0, 0.2, 0]])
    assert line.dims == 1
    assert line.weights([0.5, 0.15, 0.0]) == pytest.approx([0.0, 0.5, 0.5])


def test_layout_weights_dispatch_on_the_law():
    layout = SpatialLayout(GRID_4X4)
    assert layout.n == 16
    w = layout.weights("linear", [0, 0, 0], 0.05)
    assert w[0] == 1.0 and w[1] == pytest.approx(0.0) and w.sum() == pytest.approx(1.0)
    assert layout.weights("phantom", [0.025, 0, 0], 0.05)[:2] == pytest.approx([0.5, 0.5])
    with pytest.raises(ParameterError, match="unknown roll-off"):
        layout.weights("nearest", [0, 0, 0], 0.05)


# --------------------------------------------------------------------------- mixing
def _summed_spectrum_analysis(basis, levels, balances, weights, rng):
    """What the DSP core measures of one actuator fed the sum of the sources' noises (their per-bin powers)."""
    fs = 4800.0
    shaper = SpectralShaper(fs=fs, n_samples=int(4 * fs))
    power = sum(
        w * shaper.solve(basis.spectrum_for_balance(b), level_db=level)
        for level, b, w in zip(levels, balances, weights)
    )
    return analyze(shaper.render(power, shaper.random_phases(rng)), fs=fs, basis=basis)


def test_two_equal_sources_at_minus_and_plus_two_give_the_balance_of_their_summed_spectra(basis, spectra, rng):
    mix = mix_sources(np.ones((2, 1)), [-50.0, -50.0], [-2.0, 2.0], spectra)
    measured = _summed_spectrum_analysis(basis, [-50.0, -50.0], [-2.0, 2.0], [1.0, 1.0], rng)
    assert mix.balance[0] == pytest.approx(measured.balance, abs=1e-3)
    assert mix.level_db[0] == pytest.approx(measured.level_db, abs=1e-3)
    assert mix.level_db[0] == pytest.approx(-50.0 + 10 * math.log10(2.0), abs=1e-9)
    # the brighter source carries far more band power: the mix is not the mean balance
    assert mix.balance[0] < -0.1


def test_random_mixes_match_the_analysis_of_the_summed_spectra(basis, spectra, rng):
    for _ in range(5):
        n = int(rng.integers(2, 5))
        levels = rng.uniform(-75.0, -40.0, n)
        balances = rng.uniform(-3.0, 2.0, n)  # where the synthesis measures exactly what it is asked
        weights = rng.uniform(0.05, 1.0, n)
        mix = mix_sources(weights[:, np.newaxis], levels, balances, spectra)
        measured = _summed_spectrum_analysis(basis, levels, balances, weights, rng)
        assert mix.balance[0] == pytest.approx(measured.balance, abs=0.01)
        assert mix.level_db[0] == pytest.approx(measured.level_db, abs=0.01)


def test_a_single_source_at_the_actuator_plays_exactly_its_own_knobs(spectra, rng):
    for level, balance in zip(rng.uniform(-80, -40, 50), rng.uniform(-3.5, 3.5, 50)):
        mix = mix_sources([[1.0]], [level], [balance], spectra)
        assert mix.level_db[0] == pytest.approx(level, abs=1e-9)
        # exact to the precision the basis is stored with (8 decimals)
        assert mix.balance[0] == pytest.approx(balance, abs=1e-7)


def test_weight_w_lowers_the_level_by_10_log10_w_and_keeps_the_balance(spectra, rng):
    w = rng.uniform(1e-4, 1.0, 40)
    balance = float(rng.uniform(-3, 3))
    mix = mix_sources(w[np.newaxis], [-45.0], [balance], spectra)
    assert mix.level_db == pytest.approx(-45.0 + 10 * np.log10(w), abs=1e-9)
    assert mix.balance == pytest.approx(np.full(w.size, balance), abs=1e-7)


def test_silent_sources_and_unreached_actuators(spectra):
    mix = mix_sources([[1.0, 0.0], [0.5, 0.0]], [-math.inf, -50.0], [3.0, -1.0], spectra)
    assert mix.level_db[0] == pytest.approx(-50.0 + 10 * math.log10(0.5))
    assert mix.balance[0] == pytest.approx(-1.0)  # the silent source does not colour the mix
    assert mix.level_db[1] == -math.inf and math.isnan(mix.balance[1])


def test_mix_rejects_mismatched_or_bad_weights(spectra):
    with pytest.raises(ParameterError, match="do not match"):
        mix_sources(np.ones((3, 2)), [-50.0, -50.0], [0.0, 0.0], spectra)
    with pytest.raises(ParameterError, match="finite"):
        mix_sources([[math.nan]], [-50.0], [0.0], spectra)
    with pytest.raises(ParameterError, match="balance range"):
        TextureSpectra(spectra.basis, balance_min=1.0, balance_max=-1.0)
