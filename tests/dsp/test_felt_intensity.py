"""One definition of a felt spectrum's intensity: the paper's band, or a calibrated profile's weighting."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, WEIGHT_FLOOR_DB, profile_weighting
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.dsp.measure_band import device_band, model_iso_curve_db
from vibsynth.errors import ParameterError

FREQS = np.geomspace(10.0, 1000.0, 200)


def calibrated(response_db):
    """A profile's response, weighting and band as calibrate writes them (model iso-intensity curve)."""
    weighting, band = device_band(FREQS, response_db)
    return [[f, r] for f, r in zip(FREQS, response_db)], [[f, w] for f, w in zip(FREQS, weighting)], band


def test_the_paper_weighting_is_the_paper_s_intensity():
    x = np.random.default_rng(3).standard_normal(48000)
    assert PAPER_WEIGHTING.is_paper and PAPER_WEIGHTING.key() is None
    assert PAPER_WEIGHTING.level_db(x, fs=48000.0) == intensity_level_db(x, fs=48000.0)
    assert profile_weighting(None, None, None) is PAPER_WEIGHTING


def test_a_calibrated_weighting_is_the_skin_s_and_the_same_for_every_device():
    resonant = 10 * np.exp(-0.5 * (np.log2(FREQS / 65) / 0.4) ** 2) - 6
    flat = np.zeros(FREQS.size)
    a, b = (profile_weighting(*calibrated(r), source=f"dev{i}") for i, r in enumerate((resonant, flat)))
    skin = -model_iso_curve_db(FREQS)
    want = 10 ** (np.maximum(skin - skin.max(), WEIGHT_FLOOR_DB) / 10)
    for weighting in (a, b):
        assert weighting.kind == "weighting"
        assert np.allclose(weighting.power_weights(FREQS), want, rtol=1e-3)
    # the band shown is the device's own (drive domain): the resonance moves it
    assert a.band_hz != b.band_hz and a.key() != PAPER_WEIGHTING.key()
    # outside the profile's frequencies nothing counts
    assert a.power_weights(np.array([5.0, 2000.0])).tolist() == [0.0, 0.0]
    assert "dev0's weighting" in a.describe()


def test_a_band_alone_is_the_paper_filter_between_its_edges():
    band = profile_weighting([[10, 0], [1000, 0]], None, [100.0, 250.0], source="p")
    w = band.power_weights(np.array([100.0, np.sqrt(100 * 250), 250.0]))
    assert band.kind == "band" and np.allclose(w, [0.5, 1.0, 0.5])


@pytest.mark.parametrize(
    "args",
    [([[10, 0], [1000, 0]], None, [200.0, 100.0]), ([[10, 0]], [[10, 0], [20, 0]], None), (None, [[10, 0]], None)],
)
def test_bad_profiles_are_refused(args):
    with pytest.raises(ParameterError):
        profile_weighting(*args)


def test_the_skin_weighting_does_not_take_the_response_s_curvature_between_the_weighting_s_points():
    """R and W have different points (W resampled after its derivation): S is read at W's points, where it is -C."""
    r_freqs = np.geomspace(5.0, 2000.0, 300)
    x = r_freqs / 45.0
    r_db = 20 * np.log10(x**2 / np.abs(1 - x**2 + 1j * x / 2.0))  # a 45 Hz, Q 2 voice coil
    fine = np.geomspace(10.0, 1000.0, 1000)
    r_fine = np.interp(np.log(fine), np.log(r_freqs), r_db)
    w_fine, band = device_band(fine, r_fine)
    w_freqs = np.geomspace(10.0, 1000.0, 81)
    w_db = np.interp(np.log(w_freqs), np.log(fine), w_fine)
    weighting = profile_weighting(np.c_[r_freqs, r_db], np.c_[w_freqs, w_db], band)
    between = r_freqs[(r_freqs >= 10.0) & (r_freqs <= 1000.0)]  # mostly between W's points
    skin = -model_iso_curve_db(between)
    got = 10 * np.log10(weighting.power_weights(between))
    want = skin - skin.max()
    above = want > WEIGHT_FLOOR_DB + 10
    assert np.abs(got - want)[above].max() < 0.05 and np.all(got[~above] >= WEIGHT_FLOOR_DB)
