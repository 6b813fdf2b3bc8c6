r"""The paper's perceptual filter bank: 30 log-spaced second-order band-pass filters.

Design choice (rate independence)
---------------------------------
Every band is an *analog* 2nd-order Butterworth band-pass prototype (the same
construction the paper names for its 80-200 Hz intensity filter; as in MATLAB's
and SciPy's ``butter(2, [lo, hi], 'bandpass')`` it has 2 poles per edge), with
magnitude response

.. math:: |H_k(f)|^2 = \frac{1}{1 + \left(\frac{f^2 - f_k^2}{f\,B_k}\right)^{4}},

where ``f_k`` is the (geometric) centre and ``B_k = f_hi - f_lo`` the -3 dB
bandwidth. The edges are the geometric midpoints between adjacent centres, so
neighbouring bands cross at -3 dB and the bank covers 10-1000 Hz without gaps.

The response is evaluated exactly on the frequency grid of the signal's FFT. A
band power is the mean square of the zero-phase filtered signal, obtained by
Parseval's theorem as ``sum_b |H_k(f_b)|^2 p_b`` where ``p_b`` is the power of FFT
bin ``b``. Nothing depends on the sample rate (no bilinear-transform warping),
so a band-limited signal analysed at 2.8 kHz or 48 kHz gives the same band powers.

Why Butterworth (4 poles) and not a single biquad: a 2-pole band-pass leaks
-20 dB/decade, so the 10 Hz band of a spectrum that rises 40-55 dB to 1 kHz (the
bright end of real texture spectra) would be swamped by leakage from the loud
high bands, and no signal could measure brighter than about +2.3 balance. The
Butterworth skirts fall at -40 dB/decade.

Centres are log-spaced from 10 Hz to 1000 Hz: the paper's
``N = log(fmax/fmin) / log(1 + JND) = 29.3`` with JND = 17 % rounds to 30 filters,
an adjacent-centre ratio of ``100 ** (1/29) = 1.172``.

No I/O here: arrays in, arrays out.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.errors import ParameterError

__all__ = [
    "N_BANDS",
    "F_MIN_HZ",
    "F_MAX_HZ",
    "JND",
    "BAND_RATIO",
    "BAND_ORDER",
    "EDGE_RATIO",
    "BAND_CENTRES_HZ",
    "MIN_RATE_HZ",
    "band_centres",
    "bandpass_response",
    "butterworth_bandpass",
    "bin_powers",
    "band_powers",
    "band_powers_from_bin_powers",
    "zero_phase_filter",
    "frame_mean",
    "band_power_frames",
    "validate_signal",
]

N_BANDS = 30
F_MIN_HZ = 10.0
F_MAX_HZ = 1000.0
JND = 0.17
BAND_RATIO = (F_MAX_HZ / F_MIN_HZ) ** (1.0 / (N_BANDS - 1))
#: Butterworth prototype order of each band (2 poles per edge).
BAND_ORDER = 2
#: Band edges sit at centre / EDGE_RATIO and centre * EDGE_RATIO (geometric midpoints).
EDGE_RATIO = float(np.sqrt(BAND_RATIO))

#: Lowest accepted sample rate: the Nyquist frequency must lie above the top band's
#: upper neighbour knot (1000 Hz * 1.172 = 1172 Hz), where synthesis puts its last energy.
MIN_RATE_HZ = 2400.0

_CHUNK_BINS = 1 << 16


def band_centres(*, n_bands: int = N_BANDS, f_min: float = F_MIN_HZ, f_max: float = F_MAX_HZ) -> NDArray[np.float64]:
    """Log-spaced band centre frequencies.

    Parameters
    ----------
    n_bands : int
        Number of bands.
    f_min, f_max : float
        Lowest and highest centre frequency in Hz.

    Returns
    -------
    centres : ndarray, shape (n_bands,)
        Centre frequencies in Hz, ``f_min * (f_max/f_min) ** (k/(n_bands-1))``.
    """
    if n_bands < 2 or not (0 < f_min < f_max):
        raise ParameterError(f"need n_bands >= 2 and 0 < f_min < f_max, got {n_bands}, {f_min}, {f_max}")
    return f_min * (f_max / f_min) ** (np.arange(n_bands) / (n_bands - 1))


BAND_CENTRES_HZ = band_centres()


def butterworth_bandpass(
    freqs: ArrayLike, *, centre: ArrayLike, bandwidth: ArrayLike, order: int = BAND_ORDER
) -> NDArray[np.float64]:
    """Magnitude-squared response of analog Butterworth band-pass filters.

    Parameters
    ----------
    freqs : array_like, shape (n_freqs,)
        Frequencies in Hz (>= 0); the response at 0 Hz is 0.
    centre : array_like, shape (n_filters,)
        Geometric centre ``sqrt(f_lo * f_hi)`` of each filter, Hz.
    bandwidth : array_like, shape (n_filters,)
        ``f_hi - f_lo`` (the -3 dB bandwidth), Hz.
    order : int
        Prototype order (poles per edge).

    Returns
    -------
    response : ndarray, shape (n_filters, n_freqs)
        ``|H(f)|^2``: 1 at the centre, 0.5 at both edges.
    """
    f = np.asarray(freqs, dtype=np.float64)[np.newaxis, :]
    fc = np.atleast_1d(np.asarray(centre, dtype=np.float64))[:, np.newaxis]
    bw = np.atleast_1d(np.asarray(bandwidth, dtype=np.float64))[:, np.newaxis]
    safe_f = np.where(f > 0, f, 1.0)
    detune = np.where(f > 0, (f * f - fc * fc) / (safe_f * bw), np.inf)
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + detune ** (2 * order))


def bandpass_response(
    freqs: ArrayLike, *, centres: ArrayLike = BAND_CENTRES_HZ, order: int = BAND_ORDER
) -> NDArray[np.float64]:
    """Magnitude-squared responses of the perceptual bands.

    Parameters
    ----------
    freqs : array_like, shape (n_freqs,)
        Frequencies in Hz.
    centres : array_like, shape (n_bands,)
        Log-spaced centre frequencies; edges at ``centre * EDGE_RATIO**(+-1)``.
    order : int
        Butterworth prototype order.

    Returns
    -------
    response : ndarray, shape (n_bands, n_freqs)
    """
    fc = np.asarray(centres, dtype=np.float64)
    return butterworth_bandpass(freqs, centre=fc, bandwidth=fc * (EDGE_RATIO - 1.0 / EDGE_RATIO), order=order)


def validate_signal(x: ArrayLike, *, fs: float, min_seconds: float = 0.0) -> NDArray[np.float64]:
    """Check a mono signal and its rate at the edge of the DSP layer.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        Signal.
    fs : float
        Sample rate in Hz, at least :data:`MIN_RATE_HZ`.
    min_seconds : float
        Minimum duration.

    Returns
    -------
    x : ndarray, shape (n_samples,)
        The signal as float64.

    Raises
    ------
    ParameterError
        Not 1-D, non-finite samples, rate too low or signal too short.
    """
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise ParameterError(f"expected a mono signal of shape (n_samples,), got shape {arr.shape}")
    if not np.isfinite(fs) or fs < MIN_RATE_HZ:
        raise ParameterError(
            f"sample rate {fs:g} Hz is too low: the filter bank reaches 1000 Hz and needs at least {MIN_RATE_HZ:g} Hz"
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ParameterError(f"signal has {bad} NaN or infinite samples")
    if arr.size < max(2, int(np.ceil(min_seconds * fs))):
        raise ParameterError(f"signal is too short: {arr.size / fs:.3f} s, need at least {min_seconds:g} s")
    return arr


def bin_powers(x: ArrayLike, *, fs: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Power of each FFT bin, so that the bins sum to the signal's mean square.

    The mean (DC) is removed first: it lies outside every band and would only
    carry offsets of the sensor.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        Signal (treated as one period: no window, so a periodic loop is measured exactly).
    fs : float
        Sample rate in Hz.

    Returns
    -------
    freqs : ndarray, shape (n_samples // 2 + 1,)
        Bin frequencies in Hz.
    power : ndarray, shape (n_samples // 2 + 1,)
        Power per bin (same unit as ``x**2``).
    """
    arr = np.asarray(x, dtype=np.float64)
    n = arr.shape[-1]
    spectrum = np.fft.rfft(arr - arr.mean(axis=-1, keepdims=True), axis=-1)
    power = np.abs(spectrum) ** 2 * (2.0 / n**2)
    power[..., 0] *= 0.5
    if n % 2 == 0:
        power[..., -1] *= 0.5
    return np.fft.rfftfreq(n, 1.0 / fs).astype(np.float64), np.asarray(power, dtype=np.float64)


def _bin_chunks(n_bins: int) -> Iterator[slice]:
    for start in range(0, n_bins, _CHUNK_BINS):
        yield slice(start, min(start + _CHUNK_BINS, n_bins))


def band_powers_from_bin_powers(
    freqs: NDArray[np.float64],
    power: NDArray[np.float64],
    *,
    centres: ArrayLike = BAND_CENTRES_HZ,
    order: int = BAND_ORDER,
) -> NDArray[np.float64]:
    """Band powers from per-bin powers (Parseval, analog responses).

    Parameters
    ----------
    freqs : ndarray, shape (n_bins,)
        Bin frequencies in Hz.
    power : ndarray, shape (..., n_bins)
        Power per bin.
    centres : array_like, shape (n_bands,)
    order : int

    Returns
    -------
    band_power : ndarray, shape (..., n_bands)
        Mean square of each band-filtered signal.
    """
    centres = np.asarray(centres, dtype=np.float64)
    out = np.zeros(power.shape[:-1] + (centres.size,))
    for sl in _bin_chunks(freqs.size):  # chunks bound the (bands x bins) matrix in memory
        out += power[..., sl] @ bandpass_response(freqs[sl], centres=centres, order=order).T
    return out


def band_powers(
    x: ArrayLike, *, fs: float, centres: ArrayLike = BAND_CENTRES_HZ, order: int = BAND_ORDER
) -> NDArray[np.float64]:
    """Power in each of the 30 perceptual bands.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        Signal, any rate >= :data:`MIN_RATE_HZ`.
    fs : float
        Sample rate in Hz.
    centres : array_like, shape (n_bands,)
    order : int

    Returns
    -------
    band_power : ndarray, shape (n_bands,)
        Mean square of each zero-phase band-filtered signal (unit of ``x**2``).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> band_powers(rng.standard_normal(48000), fs=48000.0).shape
    (30,)
    """
    arr = validate_signal(x, fs=fs)
    freqs, power = bin_powers(arr, fs=fs)
    return band_powers_from_bin_powers(freqs, power, centres=centres, order=order)


def zero_phase_filter(x: NDArray[np.float64], magnitude: NDArray[np.float64]) -> NDArray[np.float64]:
    """Filter a signal by a real, non-negative magnitude response via the FFT.

    Parameters
    ----------
    x : ndarray, shape (n_samples,)
    magnitude : ndarray, shape (n_samples // 2 + 1,)
        ``|H(f)|`` on the signal's rfft grid.

    Returns
    -------
    y : ndarray, shape (n_samples,)
        Zero-phase (circular) filtered signal.
    """
    return np.fft.irfft(np.fft.rfft(x) * magnitude, n=x.shape[-1])


def frame_mean(values: NDArray[np.float64], *, window: int, hop: int) -> NDArray[np.float64]:
    """Mean of ``values`` over sliding windows.

    Parameters
    ----------
    values : ndarray, shape (n_samples,)
    window, hop : int
        Window and hop in samples (window >= 1, hop >= 1).

    Returns
    -------
    means : ndarray, shape (n_frames,)
        ``n_frames = (n_samples - window) // hop + 1`` (0 when the signal is shorter than a window).
    """
    if window < 1 or hop < 1:
        raise ParameterError(f"window and hop must be >= 1 sample, got {window}, {hop}")
    n = values.shape[-1]
    if n < window:
        return np.zeros(0)
    cumulative = np.concatenate(([0.0], np.cumsum(values)))
    starts = np.arange(0, n - window + 1, hop)
    return np.asarray((cumulative[starts + window] - cumulative[starts]) / window, dtype=np.float64)


def band_power_frames(
    x: ArrayLike,
    *,
    fs: float,
    window_s: float = 0.1,
    hop_s: float = 0.05,
    centres: ArrayLike = BAND_CENTRES_HZ,
    order: int = BAND_ORDER,
) -> NDArray[np.float64]:
    """Band powers over time: the whole signal is filtered, then its square framed.

    Filtering the whole signal first (rather than taking an FFT per window) keeps
    the narrow low bands resolved even in 100 ms windows.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    fs : float
    window_s, hop_s : float
        Window length and hop in seconds (paper: 100 ms windows, 50 ms overlap).
    centres : array_like, shape (n_bands,)
    order : int

    Returns
    -------
    frames : ndarray, shape (n_frames, n_bands)
        Mean square of each band in each window.
    """
    arr = validate_signal(x, fs=fs, min_seconds=window_s)
    arr = arr - arr.mean()
    window, hop = int(round(window_s * fs)), int(round(hop_s * fs))
    freqs = np.fft.rfftfreq(arr.size, 1.0 / fs)
    spectrum = np.fft.rfft(arr)
    centres = np.asarray(centres, dtype=np.float64)
    columns = []
    for fc in centres:  # one band at a time: memory stays O(n_samples)
        magnitude = np.sqrt(bandpass_response(freqs, centres=[fc], order=order)[0])
        band = np.fft.irfft(spectrum * magnitude, n=arr.size)
        columns.append(frame_mean(band * band, window=window, hop=hop))
    return np.stack(columns, axis=-1)
