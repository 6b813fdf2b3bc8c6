"""Filter bank: geometry, rate independence, Parseval exactness."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import resample

from vibsynth.dsp.filterbank import (
    BAND_CENTRES_HZ,
    BAND_RATIO,
    JND,
    N_BANDS,
    band_power_frames,
    band_powers,
    bandpass_response,
    bin_powers,
)
from vibsynth.errors import ParameterError


def test_bank_geometry_follows_the_paper():
    assert np.log(1000 / 10) / np.log(1 + JND) == pytest.approx(29.3, abs=0.05)  # the paper: "about 30"
    assert N_BANDS == 30
    assert BAND_CENTRES_HZ[0] == pytest.approx(10.0) and BAND_CENTRES_HZ[-1] == pytest.approx(1000.0)
    assert np.allclose(BAND_CENTRES_HZ[1:] / BAND_CENTRES_HZ[:-1], BAND_RATIO)
    assert abs(BAND_RATIO - (1 + JND)) < 0.01


def test_responses_cross_at_minus_3_db_and_peak_at_centres():
    resp = bandpass_response(BAND_CENTRES_HZ)
    assert np.allclose(np.diag(resp), 1.0)
    midpoints = np.sqrt(BAND_CENTRES_HZ[1:] * BAND_CENTRES_HZ[:-1])
    cross = bandpass_response(midpoints)
    for k in range(N_BANDS - 1):
        assert cross[k, k] == pytest.approx(0.5, abs=1e-9)
        assert cross[k + 1, k] == pytest.approx(0.5, abs=1e-9)
    assert np.all(bandpass_response([0.0]) == 0.0)


def test_parseval_bin_powers_sum_to_mean_square(rng):
    x = rng.standard_normal(4801)
    _, p = bin_powers(x, fs=8000.0)
    assert p.sum() == pytest.approx(np.var(x), rel=1e-12)


def _bandlimited_noise(rng, fs: float, seconds: float, f_max: float = 1300.0) -> np.ndarray:
    n = int(fs * seconds)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / fs)
    spec[(f > f_max) | (f < 3.0)] = 0.0
    # a non-flat spectrum so that every band differs
    spec *= 1.0 / np.sqrt(1.0 + (f / 200.0) ** 2)
    return np.fft.irfft(spec, n=n)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_same_signal_at_five_rates_gives_the_same_band_powers(seed):
    rng = np.random.default_rng(seed)
    seconds = 2.0
    x48 = _bandlimited_noise(rng, 48000.0, seconds)
    ref = 10 * np.log10(band_powers(x48, fs=48000.0))
    for fs in (2800.0, 8000.0, 10000.0, 44100.0):
        y = resample(x48, int(round(fs * seconds)))
        got = 10 * np.log10(band_powers(y, fs=fs))
        assert np.max(np.abs(got - ref)) <= 0.5, fs
        # in fact the design is rate independent to rounding:
        assert np.max(np.abs(got - ref)) < 1e-6, fs


def test_time_domain_butterworth_agrees_with_fft_analysis(rng):
    """The analog prototype is what a (pre-warped) digital Butterworth measures, within 0.5 dB."""
    from scipy.signal import butter, sosfilt

    fs = 48000.0
    x = _bandlimited_noise(rng, fs, 4.0)
    fft_db = 10 * np.log10(band_powers(x, fs=fs))
    for k in (5, 15, 25):
        fc = BAND_CENTRES_HZ[k]
        edges = [fc / np.sqrt(BAND_RATIO), fc * np.sqrt(BAND_RATIO)]
        sos = butter(2, edges, btype="bandpass", fs=fs, output="sos")
        y = sosfilt(sos, np.tile(x, 2))[x.size :]  # steady state on the periodic signal
        assert 10 * np.log10(np.mean(y**2)) == pytest.approx(fft_db[k], abs=0.5)


def test_band_power_frames_average_to_band_powers(rng):
    fs = 4000.0
    x = _bandlimited_noise(rng, fs, 3.0)
    frames = band_power_frames(x, fs=fs, window_s=0.1, hop_s=0.1)
    assert frames.shape == (30, N_BANDS)
    assert np.allclose(frames.mean(axis=0), band_powers(x, fs=fs), rtol=1e-9)


@pytest.mark.parametrize(
    "x, fs, message",
    [
        (np.zeros((10, 2)), 8000.0, "mono"),
        (np.array([0.0, np.nan, 1.0] * 100), 8000.0, "NaN"),
        (np.ones(1000), 2000.0, "too low"),
    ],
)
def test_bad_input_is_rejected_with_a_clear_message(x, fs, message):
    with pytest.raises(ParameterError, match=message):
        band_powers(x, fs=fs)
