r"""The paper's intensity model and the intensity knob.

Perceived intensity of a noisy vibration follows the power in the 80-200 Hz band,
measured through a 2nd-order Butterworth band-pass (paper, "Model of intensity
perception"; R^2 = 0.90). As in MATLAB's and SciPy's ``butter(2, [80, 200])`` the
band-pass has order 2 per edge (4 poles). We use its *analog* magnitude response,

.. math:: |H(f)|^2 = \frac{1}{1 + \left(\frac{f^2 - f_0^2}{f\,B}\right)^{2N}},
   \quad f_0 = \sqrt{80 \cdot 200}, \; B = 120, \; N = 2,

applied on the FFT grid, so the level does not depend on the sample rate.

Level unit: ``10 log10`` of the mean square of the band-filtered signal, in dB
relative to a signal of unit RMS ("dB FS band level": a full-scale white noise
has a band level far below 0 dB; a 140 Hz sine of peak 1 has -3 dB).

The **intensity knob** ``k`` (0..1) maps to a band level: ``k = 0`` is silence and
``k`` in (0, 1] spans ``range_db`` below ``ceiling_db``:
``level = ceiling_db - range_db * (1 - k)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.filterbank import (
    bin_powers,
    butterworth_bandpass,
    frame_mean,
    validate_signal,
    zero_phase_filter,
)
from vibsynth.errors import ParameterError

__all__ = [
    "INTENSITY_BAND_HZ",
    "BUTTERWORTH_ORDER",
    "DEFAULT_CEILING_DB",
    "DEFAULT_RANGE_DB",
    "SILENCE_DB",
    "intensity_response",
    "intensity_level_from_bin_powers",
    "intensity_level_db",
    "gain_to_level",
    "knob_to_level_db",
    "level_db_to_knob",
    "knob_to_gain",
    "intensity_frames_db",
    "non_stationarity_db",
]

INTENSITY_BAND_HZ = (80.0, 200.0)
BUTTERWORTH_ORDER = 2
#: Band level at knob = 1 (dB re unit RMS). The default basis' spectra put most power
#: above 200 Hz: the peak of a 4 s loop lies 19 dB (balance -3.5) to 38 dB (balance +2)
#: above the band level, so at knob 1 the noise peaks near -7 dBFS at balance 0 and
#: never above -2 dBFS at any balance, before the limiter.
DEFAULT_CEILING_DB = -40.0
#: Knob range: knob -> 0+ is ``DEFAULT_RANGE_DB`` below the ceiling.
DEFAULT_RANGE_DB = 40.0
#: Levels at or below this are treated as silence (about 1e-10 RMS).
SILENCE_DB = -200.0


def intensity_response(freqs: ArrayLike) -> NDArray[np.float64]:
    """Magnitude-squared response of the analog 80-200 Hz Butterworth band-pass.

    Parameters
    ----------
    freqs : array_like, shape (n_freqs,)
        Frequencies in Hz.

    Returns
    -------
    response : ndarray, shape (n_freqs,)
        ``|H(f)|^2`` (1 at ``sqrt(80*200)`` Hz, 0.5 at 80 and 200 Hz, 0 at DC).
    """
    low, high = INTENSITY_BAND_HZ
    response = butterworth_bandpass(freqs, centre=math.sqrt(low * high), bandwidth=high - low, order=BUTTERWORTH_ORDER)
    return np.asarray(response[0], dtype=np.float64)


def _to_db(power: float) -> float:
    return 10.0 * math.log10(power) if power > 0 else -math.inf


def intensity_level_from_bin_powers(freqs: NDArray[np.float64], power: NDArray[np.float64]) -> float:
    """Intensity level (dB) from per-bin powers.

    Parameters
    ----------
    freqs : ndarray, shape (n_bins,)
    power : ndarray, shape (n_bins,)

    Returns
    -------
    level_db : float
        dB re unit RMS; ``-inf`` for a signal with no power in the band.
    """
    return _to_db(float(power @ intensity_response(freqs)))


def intensity_level_db(x: ArrayLike, *, fs: float) -> float:
    """Intensity level of a signal: 80-200 Hz Butterworth band power in dB.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    fs : float
        Sample rate in Hz.

    Returns
    -------
    level_db : float
        dB re unit RMS (``-inf`` for silence).
    """
    freqs, power = bin_powers(validate_signal(x, fs=fs), fs=fs)
    return intensity_level_from_bin_powers(freqs, power)


def gain_to_level(x: ArrayLike, *, fs: float, target_db: float) -> float:
    """Linear gain that brings ``x`` to an intensity level.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    fs : float
    target_db : float
        Target band level in dB.

    Returns
    -------
    gain : float
        Multiply ``x`` by this to reach ``target_db``.

    Raises
    ------
    ParameterError
        The signal has no power in the intensity band, or the target is not finite.
    """
    if not math.isfinite(target_db):
        raise ParameterError(f"target level must be finite, got {target_db}")
    level = intensity_level_db(x, fs=fs)
    if level <= SILENCE_DB:
        raise ParameterError("signal has no power in the 80-200 Hz band: no gain can reach a level")
    return float(10.0 ** ((target_db - level) / 20.0))


def _check_mapping(ceiling_db: float, range_db: float) -> None:
    if not (math.isfinite(ceiling_db) and math.isfinite(range_db) and range_db > 0):
        raise ParameterError(
            f"intensity mapping needs a finite ceiling and a range > 0 dB, got {ceiling_db}, {range_db}"
        )


def knob_to_level_db(
    knob: float, *, ceiling_db: float = DEFAULT_CEILING_DB, range_db: float = DEFAULT_RANGE_DB
) -> float:
    """Band level (dB) for an intensity knob value.

    Parameters
    ----------
    knob : float
        0..1; 0 gives ``-inf`` (silence).
    ceiling_db, range_db : float
        Level at knob 1 and the span below it.

    Returns
    -------
    level_db : float
    """
    _check_mapping(ceiling_db, range_db)
    if not math.isfinite(knob) or not (0.0 <= knob <= 1.0):
        raise ParameterError(f"intensity knob must be in [0, 1], got {knob}")
    if knob == 0.0:
        return -math.inf
    return ceiling_db - range_db * (1.0 - knob)


def level_db_to_knob(
    level_db: float, *, ceiling_db: float = DEFAULT_CEILING_DB, range_db: float = DEFAULT_RANGE_DB
) -> float:
    """Equivalent intensity knob of a band level (not clamped).

    Parameters
    ----------
    level_db : float
    ceiling_db, range_db : float

    Returns
    -------
    knob : float
        ``1 + (level_db - ceiling_db) / range_db``; outside [0, 1] when the level is
        outside the knob's range (reported, not clamped), 0 for silence.
    """
    _check_mapping(ceiling_db, range_db)
    if level_db == -math.inf:
        return 0.0
    return 1.0 + (level_db - ceiling_db) / range_db


def knob_to_gain(
    knob: float,
    *,
    reference_db: float,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
) -> float:
    """Linear gain taking a signal at band level ``reference_db`` to the knob's level.

    Parameters
    ----------
    knob : float
        0..1.
    reference_db : float
        Band level of the unscaled signal.
    ceiling_db, range_db : float

    Returns
    -------
    gain : float
        0 for knob 0.
    """
    level = knob_to_level_db(knob, ceiling_db=ceiling_db, range_db=range_db)
    return 0.0 if level == -math.inf else 10.0 ** ((level - reference_db) / 20.0)


def intensity_frames_db(x: ArrayLike, *, fs: float, window_s: float = 0.1, hop_s: float = 0.05) -> NDArray[np.float64]:
    """Intensity level over time (the paper's windows: 100 ms, 50 ms overlap).

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    fs : float
    window_s, hop_s : float

    Returns
    -------
    levels_db : ndarray, shape (n_frames,)
        Band level of each window in dB (``-inf`` for silent windows).
    """
    arr = validate_signal(x, fs=fs, min_seconds=window_s)
    arr = arr - arr.mean()
    magnitude = np.sqrt(intensity_response(np.fft.rfftfreq(arr.size, 1.0 / fs)))
    band = zero_phase_filter(arr, magnitude)
    power = frame_mean(band * band, window=int(round(window_s * fs)), hop=int(round(hop_s * fs)))
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(power)


def non_stationarity_db(x: ArrayLike, *, fs: float, window_s: float = 0.1, hop_s: float = 0.05) -> float:
    """The paper's non-stationarity metric: std of the windowed intensity level.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    fs : float
    window_s, hop_s : float

    Returns
    -------
    std_db : float
        Standard deviation (dB) of the window levels; silent windows are floored at
        :data:`SILENCE_DB`. 0 for a signal shorter than two windows.
    """
    levels = intensity_frames_db(x, fs=fs, window_s=window_s, hop_s=hop_s)
    if levels.size < 2:
        return 0.0
    return float(np.std(np.maximum(levels, SILENCE_DB)))
