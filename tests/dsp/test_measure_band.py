"""A device's weighting and band: the paper's band from the paper's (illustrative) device, and shifts."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.measure import response_freqs
from vibsynth.dsp.measure_band import device_band, intensity_band, model_iso_curve_db, sensitivity_weighting_db
from vibsynth.errors import ParameterError

# The shipped illustrative profile (config/actuators/hapcoil-example.yaml), as points.
HAPCOIL = np.array(
    [[10, -32.3], [15, -25.0], [20, -19.7], [30, -11.5], [40, -4.7], [50, 1.8], [58, 6.9], [65, 9.5], [72, 9.0],
     [85, 6.2], [100, 4.2], [150, 1.7], [200, 0.9], [300, 0.4], [500, 0.1], [700, 0.1], [1000, 0.0]]
)  # fmt: skip


def hapcoil_db(f):
    return np.interp(np.log(f), np.log(HAPCOIL[:, 0]), HAPCOIL[:, 1])


def test_paper_device_gives_the_paper_band():
    f = response_freqs()
    weighting, (lo, hi) = device_band(f, hapcoil_db(f))
    assert lo == pytest.approx(80.0, rel=0.02) and hi == pytest.approx(200.0, rel=0.02)
    assert weighting.max() == 0.0


def test_flat_device_band_is_centred_on_the_curve_and_a_resonance_pulls_it():
    f = response_freqs()
    lo, hi = device_band(f, np.zeros(f.size))[1]
    assert np.sqrt(lo * hi) == pytest.approx(150.0, rel=0.01)
    # a 1 dB-per-octave-steep curve: edges where curvature * x^2 = 3
    assert hi / lo == pytest.approx(2 ** (2 * np.sqrt(3 / 9.8)), rel=0.01)
    low_res = np.where(f < 60, 0.0, 0.0) + 12.0 * np.exp(-(np.log2(f / 40.0) ** 2) / 0.1)
    lo2, hi2 = device_band(f, low_res)[1]
    assert lo2 < lo


def test_weighting_is_response_minus_curve_and_band_edges_interpolate():
    f = np.array([10.0, 100.0, 1000.0])
    w = sensitivity_weighting_db(f, [0.0, 10.0, 0.0], [10.0, 1000.0], [0.0, 0.0])
    assert np.allclose(w, [-10.0, 0.0, -10.0])
    lo, hi = intensity_band(f, w, within_db=5.0)
    assert lo == pytest.approx(10**1.5) and hi == pytest.approx(10**2.5)
    assert model_iso_curve_db([150.0, 300.0])[1] == pytest.approx(9.8)


def test_bad_curves_refused():
    with pytest.raises(ParameterError):
        sensitivity_weighting_db([1.0, 2.0], [0.0], [1.0, 2.0], [0.0, 0.0])
    with pytest.raises(ParameterError):
        sensitivity_weighting_db([2.0, 1.0], [0.0, 0.0], [1.0, 2.0], [0.0, 0.0])
    with pytest.raises(ParameterError):
        intensity_band([1.0, 2.0], [0.0, np.nan])
    with pytest.raises(ParameterError):
        intensity_band([1.0, 2.0], [0.0, -1.0], within_db=0)
