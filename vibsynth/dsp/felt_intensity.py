r"""The intensity of a felt spectrum: the paper's band, or a calibrated device's own weighting.

One definition, used wherever vibsynth turns a spectrum into an intensity level: the noise
bank's normalisation (what the intensity knob means), ``vibsynth analyze --profile``, presets
made from recordings, and the per-channel trims (:mod:`vibsynth.dsp.channel_trim`).

The level is ``10 log10 sum_f P(f) w(f)`` (dB re unit RMS), where ``P`` is the per-bin power
of the **felt** signal (the actuator's output: what an accelerometer on it records; for an
uncompensated actuator, the drive times its response) and ``w`` a power weighting:

* **paper** (the default, and any profile without a calibration): the paper's 80-200 Hz
  2nd-order Butterworth band-pass (:func:`vibsynth.dsp.intensity.intensity_response`).
* **weighting**: a calibrated profile stores its sensitivity weighting ``W(f) = R(f) - C(f)``
  (response minus iso-intensity curve, 0 dB at its top: how strongly a unit of *drive* is
  felt, :mod:`vibsynth.dsp.measure_band`). A unit of *felt* signal is then felt as
  ``S(f) = W(f) - R(f) = -C(f)`` + a constant: the skin's sensitivity as that calibration
  measured it. ``w = 10^(S/10)``, 0 dB at its top, zero outside the profile's frequencies.
  Summing the *drive* spectrum under the device's own weighting ``W`` gives the same number
  up to that constant: the knob's level is the drive's level in the device's own weighting.
* **band**: a profile with ``band_hz`` but no ``weighting``: the paper's filter shape
  (2nd-order Butterworth band-pass) between those edges.

Two devices calibrated with the same iso-intensity curve get the same ``w`` (``S = -C``
does not depend on the device), so the same knobs give the same felt intensity on both; a
lab's measured curve changes ``w`` for the device (and grip) it was measured on.
No I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.filterbank import bin_powers, butterworth_bandpass, validate_signal
from vibsynth.dsp.intensity import BUTTERWORTH_ORDER, INTENSITY_BAND_HZ, intensity_response
from vibsynth.dsp.measure_band import intensity_band
from vibsynth.errors import ParameterError

__all__ = ["WEIGHT_FLOOR_DB", "IntensityWeighting", "PAPER_WEIGHTING", "profile_weighting"]

#: The weighting never goes below this (dB re its top) inside the profile's frequencies.
WEIGHT_FLOOR_DB = -60.0

Points = Sequence[Sequence[float]]


def _interp_db(points: NDArray[np.float64], freqs: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points (k, 2) [Hz, dB] on log-frequency at ``freqs`` (held at the ends)."""
    safe = np.where(freqs > 0, freqs, points[0, 0])
    return np.asarray(np.interp(np.log(safe), np.log(points[:, 0]), points[:, 1]), dtype=np.float64)


def _check_points(points: Points | None, what: str) -> NDArray[np.float64]:
    arr = np.asarray(points if points is not None else (), dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 2:
        raise ParameterError(f"{what} needs at least two [Hz, dB] points")
    if not np.all(np.isfinite(arr)) or np.any(arr[:, 0] <= 0) or np.any(np.diff(arr[:, 0]) <= 0):
        raise ParameterError(f"{what}: frequencies must be > 0 and increasing, values finite")
    return arr


@dataclass(frozen=True)
class IntensityWeighting:
    """How a felt spectrum is weighted into an intensity level (see the module notes).

    Attributes
    ----------
    kind : {"paper", "weighting", "band"}
    points : tuple of (float, float)
        ``kind == "weighting"``: the felt-domain weighting ``S`` [Hz, dB], 0 dB at its top.
    band_hz : (float, float)
        The band (the paper's 80-200 Hz, or the profile's ``band_hz``), for display and ``kind == "band"``.
    source : str
        Where it comes from, for messages (``the paper's 80-200 Hz band``, ``profile vest-ch1``).
    """

    kind: str = "paper"
    points: tuple[tuple[float, float], ...] = ()
    band_hz: tuple[float, float] = INTENSITY_BAND_HZ
    source: str = "the paper's 80-200 Hz band"

    @property
    def is_paper(self) -> bool:
        """True for the paper's default band."""
        return self.kind == "paper"

    def power_weights(self, freqs: ArrayLike) -> NDArray[np.float64]:
        """Power weighting ``w(f)`` (1 at its top).

        Parameters
        ----------
        freqs : array_like, shape (n,)
            Hz.

        Returns
        -------
        weights : ndarray, shape (n,)
        """
        f = np.asarray(freqs, dtype=np.float64)
        if self.kind == "paper":
            return intensity_response(f)
        if self.kind == "band":
            low, high = self.band_hz
            response = butterworth_bandpass(
                f, centre=math.sqrt(low * high), bandwidth=high - low, order=BUTTERWORTH_ORDER
            )
            return np.asarray(response[0], dtype=np.float64)
        pts = np.asarray(self.points, dtype=np.float64)
        inside = (f >= pts[0, 0]) & (f <= pts[-1, 0])
        return np.where(inside, 10.0 ** (_interp_db(pts, f) / 10.0), 0.0)

    def level_from_bin_powers(self, freqs: NDArray[np.float64], power: NDArray[np.float64]) -> float:
        """Intensity level (dB re unit RMS) of per-bin powers; ``-inf`` with no power under the weighting.

        Parameters
        ----------
        freqs : ndarray, shape (n_bins,)
        power : ndarray, shape (n_bins,)
        """
        total = float(power @ self.power_weights(freqs))
        return 10.0 * math.log10(total) if total > 0 else -math.inf

    def levels_from_bin_powers(self, freqs: NDArray[np.float64], power: NDArray[np.float64]) -> NDArray[np.float64]:
        """Linear weighted powers of several spectra.

        Parameters
        ----------
        freqs : ndarray, shape (n_bins,)
        power : ndarray, shape (n_spectra, n_bins)

        Returns
        -------
        weighted : ndarray, shape (n_spectra,)
            ``sum_f P w`` (not in dB).
        """
        return np.asarray(power @ self.power_weights(freqs), dtype=np.float64)

    def level_db(self, x: ArrayLike, *, fs: float) -> float:
        """Intensity level of a felt signal (dB re unit RMS; ``-inf`` for silence).

        Parameters
        ----------
        x : array_like, shape (n_samples,)
        fs : float
        """
        freqs, power = bin_powers(validate_signal(x, fs=fs), fs=fs)
        return self.level_from_bin_powers(freqs, power)

    def describe(self) -> str:
        """``80-200 Hz (the paper's band)`` or ``103-221 Hz (profile vest-ch1's weighting)``."""
        low, high = self.band_hz
        what = {"paper": "the paper's band", "band": f"{self.source}'s band"}.get(
            self.kind, f"{self.source}'s weighting"
        )
        return f"{low:.0f}-{high:.0f} Hz ({what})"

    def key(self) -> list[object] | None:
        """JSON-able identity for cache keys (None for the paper's band)."""
        if self.kind == "paper":
            return None
        if self.kind == "band":
            return ["band", list(self.band_hz)]
        return ["weighting", [list(p) for p in self.points]]


#: The paper's 80-200 Hz band (the default everywhere).
PAPER_WEIGHTING = IntensityWeighting()


def profile_weighting(
    response: Points | None,
    weighting: Points | None,
    band_hz: Sequence[float] | None,
    *,
    source: str = "the profile",
) -> IntensityWeighting:
    """The intensity weighting a profile calibrates (the paper's band when it has none).

    Parameters
    ----------
    response : sequence of [Hz, dB], shape (k, 2), or None
        The profile's response ``R``.
    weighting : sequence of [Hz, dB], shape (m, 2), or None
        Its sensitivity weighting ``W`` (drive domain).
    band_hz : [low, high] or None
    source : str
        Named in messages and :meth:`IntensityWeighting.describe`.

    Returns
    -------
    weighting : IntensityWeighting
        ``kind="weighting"`` with ``S = W - R`` (0 dB at its top, floored at
        :data:`WEIGHT_FLOOR_DB`) at the weighting's points (the response interpolated there); ``kind="band"`` with only
        ``band_hz``; :data:`PAPER_WEIGHTING` with neither.
    """
    band: tuple[float, float] | None = None
    if band_hz is not None:
        low, high = (float(v) for v in band_hz)
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low < high):
            raise ParameterError(f"{source}: band_hz must be [low, high] with 0 < low < high, got {list(band_hz)!r}")
        band = (low, high)
    if weighting is None:
        if band is None:
            return PAPER_WEIGHTING
        return IntensityWeighting(kind="band", band_hz=band, source=source)
    w = _check_points(weighting, f"{source}: weighting")
    r = _check_points(response, f"{source}: response")
    grid = w[:, 0]  # where W was derived from R: R read there makes S exact at every point
    s = w[:, 1] - _interp_db(r, grid)
    s = np.maximum(s - s.max(), WEIGHT_FLOOR_DB)
    points = tuple((float(f), round(float(v), 4)) for f, v in zip(grid, s, strict=True))
    if band is None:
        band = intensity_band(grid, w[:, 1])
    return IntensityWeighting(kind="weighting", points=points, band_hz=band, source=source)
