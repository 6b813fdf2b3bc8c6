r"""A device's own intensity band, from its measured response and an iso-intensity curve.

The paper's intensity band (80-200 Hz) is "the combination of the human tactile sensory
curve for sine waves and the actuator's frequency response": a drive voltage at frequency
``f`` is felt in proportion to the actuator's response ``R(f)`` (acceleration per volt, dB)
times the skin's sensitivity ``S(f)`` (the inverse of the acceleration an iso-intensity
curve asks for, ``S = -C(f)`` in dB). Their sum,

.. math:: W(f) = R(f) - C(f) - \max_f\,(R - C),

is the device's **sensitivity weighting** (0 dB where a volt is felt most), and its
**intensity band** is where ``W`` lies within :data:`BAND_WITHIN_DB` of its maximum: the
contiguous run of frequencies around the maximum, edges interpolated on log-frequency.
3 dB is the choice because the paper's band edges are the -3 dB points of its Butterworth
band-pass: the weighting's half-power band plays the same role.

:func:`model_iso_curve_db` is a U-shaped *model* of an iso-intensity curve in acceleration
(``curvature (log2 f / centre)^2`` dB): with :data:`MODEL_ISO_CENTRE_HZ` and
:data:`MODEL_ISO_CURVATURE_DB` it gives, for the shipped illustrative ``hapcoil-example``
profile, the paper's 80-200 Hz (80.0-200.7 Hz). The paper does not publish its Fig. 1b
numbers: these two constants were fitted to that one fact and are no measurement; a lab
measures its own curve (``vibsynth lab``, iso-intensity sines) and passes it here.
No I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.errors import ParameterError

__all__ = [
    "BAND_WITHIN_DB",
    "MODEL_ISO_CENTRE_HZ",
    "MODEL_ISO_CURVATURE_DB",
    "model_iso_curve_db",
    "sensitivity_weighting_db",
    "intensity_band",
    "device_band",
]

#: The band is where the weighting is within this of its maximum (the Butterworth's -3 dB edges).
BAND_WITHIN_DB = 3.0
#: The U-shaped model curve's bottom (Hz) and curvature (dB per octave squared), see the module notes.
MODEL_ISO_CENTRE_HZ = 150.0
MODEL_ISO_CURVATURE_DB = 9.8


def _grid(freqs: ArrayLike, values: ArrayLike, what: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    f = np.asarray(freqs, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if f.ndim != 1 or f.shape != v.shape or f.size < 2:
        raise ParameterError(f"{what}: frequencies and values must be two 1-D arrays of one length >= 2")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(v))) or np.any(f <= 0) or np.any(np.diff(f) <= 0):
        raise ParameterError(f"{what}: frequencies must be finite, > 0 and increasing, values finite")
    return f, v


def model_iso_curve_db(
    freqs: ArrayLike, *, centre_hz: float = MODEL_ISO_CENTRE_HZ, curvature_db: float = MODEL_ISO_CURVATURE_DB
) -> NDArray[np.float64]:
    """A U-shaped model iso-intensity curve: acceleration for equal intensity, dB re its minimum.

    Parameters
    ----------
    freqs : array_like, shape (n,)
        Hz, > 0.
    centre_hz, curvature_db : float

    Returns
    -------
    curve_db : ndarray, shape (n,)
    """
    f = np.asarray(freqs, dtype=np.float64)
    if np.any(f <= 0) or not (centre_hz > 0 and curvature_db >= 0):
        raise ParameterError("a model iso-intensity curve needs frequencies > 0, centre > 0, curvature >= 0")
    return np.asarray(curvature_db * np.log2(f / centre_hz) ** 2, dtype=np.float64)


def sensitivity_weighting_db(
    freqs: ArrayLike, response_db: ArrayLike, iso_freqs: ArrayLike, iso_db: ArrayLike
) -> NDArray[np.float64]:
    """How strongly a unit drive is felt at each frequency: ``R - C``, 0 dB at its maximum.

    Parameters
    ----------
    freqs : array_like, shape (n,)
        The response's grid (Hz, increasing).
    response_db : array_like, shape (n,)
        The device's response (acceleration per unit drive, dB; absolute or relative).
    iso_freqs : array_like, shape (k,)
        Where the iso-intensity curve was measured (Hz, increasing, k >= 2).
    iso_db : array_like, shape (k,)
        Acceleration felt as equally intense (dB, any reference); interpolated on
        log-frequency, held at its ends.

    Returns
    -------
    weighting_db : ndarray, shape (n,)
        <= 0, 0 at the most sensitive frequency.
    """
    f, r = _grid(freqs, response_db, "response")
    fi, c = _grid(iso_freqs, iso_db, "iso-intensity curve")
    w = r - np.interp(np.log(f), np.log(fi), c)
    return np.asarray(w - np.max(w), dtype=np.float64)


def intensity_band(
    freqs: ArrayLike, weighting_db: ArrayLike, *, within_db: float = BAND_WITHIN_DB
) -> tuple[float, float]:
    """The contiguous band around the weighting's maximum where it is within ``within_db`` of it.

    Parameters
    ----------
    freqs : array_like, shape (n,)
        Hz, increasing.
    weighting_db : array_like, shape (n,)
        :func:`sensitivity_weighting_db`.
    within_db : float
        > 0.

    Returns
    -------
    low_hz, high_hz : float
        Edges interpolated on log-frequency where the weighting crosses ``-within_db``; a band
        reaching the end of the grid stops there.
    """
    f, w = _grid(freqs, weighting_db, "weighting")
    if not (math.isfinite(within_db) and within_db > 0):
        raise ParameterError(f"within_db must be > 0, got {within_db!r}")
    w = w - np.max(w)
    top = int(np.argmax(w))
    edge = -float(within_db)
    lo = top
    while lo > 0 and w[lo - 1] >= edge:
        lo -= 1
    hi = top
    while hi < w.size - 1 and w[hi + 1] >= edge:
        hi += 1

    def cross(i: int, j: int) -> float:  # i inside, j outside the band
        t = (w[i] - edge) / (w[i] - w[j])
        return float(math.exp(math.log(f[i]) + t * (math.log(f[j]) - math.log(f[i]))))

    low = cross(lo, lo - 1) if lo > 0 else float(f[0])
    high = cross(hi, hi + 1) if hi < w.size - 1 else float(f[-1])
    return low, high


def device_band(
    freqs: ArrayLike,
    response_db: ArrayLike,
    iso_freqs: ArrayLike | None = None,
    iso_db: ArrayLike | None = None,
    *,
    within_db: float = BAND_WITHIN_DB,
) -> tuple[NDArray[np.float64], tuple[float, float]]:
    """The weighting and band of a device (default iso-intensity curve: :func:`model_iso_curve_db`).

    Returns
    -------
    weighting_db : ndarray, shape (n,)
    band : (float, float)
    """
    f = np.asarray(freqs, dtype=np.float64)
    if iso_freqs is None or iso_db is None:
        iso_freqs, iso_db = f, model_iso_curve_db(f)
    weighting = sensitivity_weighting_db(f, response_db, iso_freqs, iso_db)
    return weighting, intensity_band(f, weighting, within_db=within_db)
