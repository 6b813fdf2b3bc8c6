"""Per-channel trims: a V1 tilt is a balance offset, a flat shift a gain, the rest is reported as residual."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibsynth.dsp.channel_trim import ChannelTrim, channel_trim
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, profile_weighting
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import ParameterError
from vibsynth.formats.basis_file import default_basis

BALANCES = np.linspace(-2.0, 2.0, 17)


@pytest.fixture(scope="module")
def basis():
    return default_basis()


@pytest.fixture(scope="module")
def texture(basis):
    """Per-bin powers of the texture at BALANCES (a 2 s loop at 4.8 kHz), as the bank solves them."""
    shaper = SpectralShaper(fs=4800.0, n_samples=9600)
    weights = np.stack([shaper.solve_balance(basis, float(b), level_db=0.0) for b in BALANCES])
    return shaper.freqs, shaper.power_envelope(weights)


def v1_of(basis, freqs):
    """V1 as a function of frequency (interpolated between the band centres on log-frequency)."""
    return np.interp(np.log(np.maximum(freqs, 1.0)), np.log(basis.centres_hz), basis.v1)


@pytest.mark.parametrize("tilt", [-6.0, 3.0, 8.0])
def test_a_pure_v1_tilt_is_a_balance_offset_of_the_tilt(basis, texture, tilt):
    freqs, power = texture
    trim = channel_trim(basis, freqs, power, BALANCES, tilt * v1_of(basis, freqs))
    # the tilt moves t1 by itself (within the bands' smoothing of a 1/6-octave-wide V1) ...
    assert trim.t1_shift == pytest.approx(tilt, rel=0.01)
    # ... and the offset takes it back, in knob units
    assert trim.balance_offset == pytest.approx(float(basis.balance_from_t1(-tilt)), rel=0.01)
    assert trim.residual_rms_db < 0.02 * abs(tilt) and trim.balance_spread < 0.002


@pytest.mark.parametrize("shift", [-6.0, 4.5])
def test_a_flat_shift_is_a_gain_only(basis, texture, shift):
    freqs, power = texture
    trim = channel_trim(basis, freqs, power, BALANCES, np.full(freqs.size, shift))
    assert trim.balance_offset == pytest.approx(0.0, abs=1e-12)
    assert trim.gain_db == pytest.approx(-shift, abs=1e-9)
    assert trim.gain == pytest.approx(10 ** (-shift / 20))
    assert np.allclose(trim.gain_curve_db, -shift) and trim.residual_max_db < 1e-9
    assert not trim.limited and not trim.is_identity


def test_a_resonance_leaves_a_residual_and_a_gain_that_follows_the_balance(basis, texture):
    freqs, power = texture
    bump = 6.0 * np.exp(-0.5 * (np.log2(np.maximum(freqs, 1.0) / 120.0) / 0.3) ** 2)
    trim = channel_trim(basis, freqs, power, BALANCES, bump)
    assert trim.residual_db.shape == (basis.n_bands,)
    assert 0.5 < trim.residual_rms_db < trim.residual_max_db < 6.0
    # the residual is what is left: orthogonal to V1 and to a level change
    assert abs(float(trim.residual_db @ basis.v1)) < 1e-6 and abs(float(trim.residual_db.mean())) < 1e-6
    # a bump in the intensity band needs less gain at a bright balance (the band holds leakage there)
    curve = trim.gain_curve_db
    assert curve[0] < curve[-1] and trim.gain_spread_db > 1.0
    # applied at the channel's effective position, the curve gives the bank's level back exactly
    scale = 10 ** (bump / 10)
    own = PAPER_WEIGHTING.levels_from_bin_powers(freqs, power * scale)
    ref = PAPER_WEIGHTING.levels_from_bin_powers(freqs, power)
    assert np.allclose(10 * np.log10(own / ref) + curve, 0.0)


def test_the_gain_is_bounded_and_says_so(basis, texture):
    freqs, power = texture
    trim = channel_trim(basis, freqs, power, BALANCES, np.full(freqs.size, -20.0), max_gain_db=12.0)
    assert trim.gain_db == 12.0 and trim.limited and trim.wanted_gain_db == pytest.approx(20.0)
    assert "limited" in trim.describe()


def test_the_channel_s_own_weighting_sets_its_level(basis, texture):
    freqs, power = texture
    response = [[10.0, 0.0], [1000.0, 0.0]]
    narrow = profile_weighting(response, None, [150.0, 200.0], source="narrow")
    trim = channel_trim(basis, freqs, power, BALANCES, np.zeros(freqs.size), channel_weighting=narrow)
    own = narrow.levels_from_bin_powers(freqs, power)
    ref = PAPER_WEIGHTING.levels_from_bin_powers(freqs, power)
    assert np.allclose(trim.gain_curve_db, -10 * np.log10(own / ref))


def test_identity_and_bad_shapes(basis, texture):
    freqs, power = texture
    assert ChannelTrim().is_identity and np.all(ChannelTrim().gains(5) == 1.0)
    with pytest.raises(ParameterError):
        channel_trim(basis, freqs, power, BALANCES, np.zeros(freqs.size - 1))
    with pytest.raises(ParameterError):
        channel_trim(basis, freqs, power, BALANCES[::-1], np.zeros(freqs.size))
    with pytest.raises(ParameterError):
        channel_trim(basis, freqs, power, BALANCES, np.full(freqs.size, math.nan))
    with pytest.raises(ParameterError, match="17 bank levels"):
        channel_trim(basis, freqs, power, BALANCES, np.ones(freqs.size)).gains(49)
