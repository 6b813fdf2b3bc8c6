"""Onsets: a rise of the short-term power over the recent past, in one or more bands.

Per hop, each band's power over the last ``short`` hops is compared with its mean over the
``reference`` hops before them (a 60 ms memory). The onset function is the weighted sum of the
bands' rises in dB (only rises count). An onset fires on the first hop where the function
crosses ``threshold_db`` (then not again for ``refractory`` hops); its raw strength is the
rise over 30 dB (0..1), scaled by the caller (the tracker multiplies by the intensity knob).
A short window of about 5 ms keeps the detection within one or two hops of the onset.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.follow.stream import Ring

__all__ = [
    "OnsetDetector",
    "ONSET_THRESHOLD_DB",
    "FULL_STRENGTH_DB",
    "ONSET_SCALE_FLOOR",
    "TRANSIENT_BOOST",
    "transient_peak",
]

#: Rise (dB, weighted over bands) that makes an onset.
ONSET_THRESHOLD_DB = 9.0
#: Rise that gives strength 1.
FULL_STRENGTH_DB = 30.0
#: The tracker scales an onset's raw strength by ``max(intensity knob, this)`` (a quiet sound's
#: onsets still play); the live follower divides by the same to recover the rise.
ONSET_SCALE_FLOOR = 0.25
#: Knob units an onset of strength 1 lifts the intensity by (10 dB at the default 40 dB range),
#: live (control/follow/transients.py) and offline (app/follow_offline.py) alike.
TRANSIENT_BOOST = 0.25
_SHORT_S = 0.005
_REFERENCE_S = 0.06
_REFRACTORY_S = 0.05
_FLOOR = 1e-20


def transient_peak(intensity: ArrayLike, strength: ArrayLike) -> NDArray[np.float64]:
    """Intensity knob an onset lifts the curve to: ``intensity + strength * TRANSIENT_BOOST``, at most 1.

    Parameters
    ----------
    intensity, strength : array_like, broadcastable
        The curve's intensity knob where the onset lands, and the onset's strength (0..1].

    Returns
    -------
    ndarray
        The peak, same shape as the broadcast inputs (0-d for scalars).
    """
    return np.minimum(1.0, np.asarray(intensity, dtype=np.float64) + np.asarray(strength) * TRANSIENT_BOOST)


class OnsetDetector:
    """Onsets from per-hop band powers.

    Parameters
    ----------
    hop_s : float
        Frame period.
    weights : array_like, shape (n_bands,)
        Weight of each band's rise (they need not sum to 1).
    threshold_db : float
    """

    def __init__(self, hop_s: float, weights: ArrayLike, *, threshold_db: float = ONSET_THRESHOLD_DB) -> None:
        self.weights = np.asarray(weights, dtype=np.float64)
        self.short = max(1, int(round(_SHORT_S / hop_s)))
        self.reference = max(2, int(round(_REFERENCE_S / hop_s)))
        self.refractory = max(1, int(math.ceil(_REFRACTORY_S / hop_s)))
        self.threshold_db = float(threshold_db)
        self._ring = Ring(self.short + self.reference, self.weights.size)
        self._since = self.refractory
        self._armed = True

    def reset(self) -> None:
        self._ring.reset()
        self._since = self.refractory
        self._armed = True

    def __call__(
        self, hop_power: NDArray[np.float64], floor_power: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Onset function and raw strengths of consecutive hops.

        Parameters
        ----------
        hop_power : ndarray, shape (n_bands, k)
            Mean power of each band in each hop.
        floor_power : float
            Powers below this count as this (rises out of silence are measured from it).

        Returns
        -------
        rise_db : ndarray, shape (k,)
            Weighted rise (onset function).
        strength : ndarray, shape (k,)
            0 where no onset fires, else the rise mapped to (0, 1].
        """
        k = hop_power.shape[1]
        rise = np.zeros(k)
        strength = np.zeros(k)
        floor = max(float(floor_power), _FLOOR)
        for i in range(k):
            self._ring.push(hop_power[:, i])
            rows = self._ring.last(self.short + self.reference)
            if rows.shape[0] <= self.short:
                continue
            short = np.maximum(rows[-self.short :].mean(axis=0), floor)
            ref = np.maximum(rows[: -self.short].mean(axis=0), floor)
            r = float(self.weights @ np.maximum(0.0, 10.0 * np.log10(short / ref)))
            rise[i] = r
            self._since += 1
            if r < 0.5 * self.threshold_db:
                self._armed = True
            if r >= self.threshold_db and self._armed and self._since >= self.refractory:
                strength[i] = min(1.0, r / FULL_STRENGTH_DB)
                self._since = 0
                self._armed = False
        return rise, strength
