"""Onsets: a rise of the short-term power over the recent past, in one or more bands.

Per hop, each band's mean power over the newest ``short_s`` is compared with its mean over the
``reference_s`` before; the onset function is the weighted sum of the bands' rises in dB (only
rises count). An onset fires on the first hop where the function crosses its threshold (see
:class:`OnsetDetector` for re-arming, the refractory time and the louder retrigger); its raw
strength is the rise over 30 dB (0..1), scaled by the caller (the tracker multiplies by the
intensity knob). Audio mode runs it on five bands every 2.5 ms against the 20 ms before
(:mod:`vibsynth.dsp.follow.audio`), vibration mode on the broadband power every frame against
the 60 ms before (the defaults here). The rises of a block are computed at once (cumulative sums
over the block and the window's history); only the firing rule runs hop by hop, so the cost per
block is bounded by its hops.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

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

    Per hop, each band's mean power over the newest ``short_s`` is compared with its mean over the
    ``reference_s`` before; the onset function is the weighted sum of the bands' rises in dB (only
    rises count). An onset fires on the first hop where the function reaches ``threshold_db``, once
    the function has fallen below half the threshold since the last onset (re-armed) and
    ``refractory_s`` has passed. With ``retrigger_db``, an onset fires within the refractory time
    too, ``retrigger_s`` or more after the last, when the sound is then ``retrigger_db`` louder than
    it was at its loudest in the ``retrigger_s`` after the last (the bands' weighted power over
    ``short_s``): a hit 10-30 ms after a faint pre-echo is not lost to the refractory time, and
    a hit's own attack (loudest within a few ms) does not fire twice.

    Parameters
    ----------
    hop_s : float
        Period of the band powers fed.
    weights : array_like, shape (n_bands,)
        Weight of each band's rise (they need not sum to 1).
    threshold_db : float
    short_s, reference_s, refractory_s : float
        The windows (rounded to whole hops: ``short`` and ``reference`` hops at least 1 and 2).
    retrigger_db : float or None
        See above; None: never within the refractory time.
    retrigger_s : float
    """

    def __init__(
        self,
        hop_s: float,
        weights: ArrayLike,
        *,
        threshold_db: float = ONSET_THRESHOLD_DB,
        short_s: float = _SHORT_S,
        reference_s: float = _REFERENCE_S,
        refractory_s: float = _REFRACTORY_S,
        retrigger_db: float | None = None,
        retrigger_s: float = 0.010,
    ) -> None:
        self.weights = np.asarray(weights, dtype=np.float64)
        self.short = max(1, int(round(short_s / hop_s)))
        self.reference = max(2, int(round(reference_s / hop_s)))
        self.refractory = max(1, int(math.ceil(refractory_s / hop_s - 1e-9)))
        self.threshold_db = float(threshold_db)
        self.retrigger_db = retrigger_db
        self.retrigger_gap = max(1, int(math.ceil(retrigger_s / hop_s - 1e-9)))
        self._history = np.zeros((0, self.weights.size))
        self._since = self.refractory
        self._armed = True
        self._fired_db = 0.0

    def reset(self) -> None:
        self._history = np.zeros((0, self.weights.size))
        self._since = self.refractory
        self._armed = True
        self._fired_db = 0.0

    def _rise(
        self, hop_power: NDArray[np.float64], floor_power: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Per hop of ``hop_power`` (see :meth:`__call__`), each shape (k,): the weighted rise (0
        until more than ``short`` hops have been seen), the dB of the bands' weighted power over the
        newest ``short`` hops, and whether the hop had a reference. Advances the history."""
        k = hop_power.shape[1]
        total = self.short + self.reference
        rows = np.concatenate((self._history, np.asarray(hop_power, dtype=np.float64).T), axis=0)
        h = self._history.shape[0]
        self._history = rows[max(0, rows.shape[0] - (total - 1)) :]
        cum = np.concatenate((np.zeros((1, rows.shape[1])), np.cumsum(rows, axis=0)))
        end = h + 1 + np.arange(k)
        start = np.maximum(0, end - total)
        mid = end - self.short
        valid = mid > start
        floor = max(float(floor_power), _FLOOR)
        short = np.maximum((cum[end] - cum[mid]) / self.short, floor)
        ref = np.maximum((cum[mid] - cum[start]) / np.maximum(1, mid - start)[:, np.newaxis], floor)
        rise = np.maximum(0.0, 10.0 * np.log10(short / ref)) @ self.weights
        level = 10.0 * np.log10(np.maximum(short @ self.weights, _FLOOR))
        return np.where(valid, rise, 0.0), level, valid

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
        rise, level, valid = self._rise(hop_power, floor_power)
        strength = np.zeros(rise.size)
        threshold = self.threshold_db
        retrigger = math.inf if self.retrigger_db is None else self.retrigger_db
        for i in np.flatnonzero(valid).tolist():
            r = float(rise[i])
            self._since += 1
            if r < 0.5 * threshold:
                self._armed = True
            if self._since < self.retrigger_gap:
                self._fired_db = max(self._fired_db, float(level[i]))
            if r < threshold:
                continue
            louder = self._since >= self.retrigger_gap and float(level[i]) >= self._fired_db + retrigger
            if (self._armed and self._since >= self.refractory) or louder:
                strength[i] = min(1.0, r / FULL_STRENGTH_DB)
                self._since = 0
                self._armed = False
                self._fired_db = float(level[i])
        return rise, strength
