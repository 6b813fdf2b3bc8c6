"""A stereo input's balance as a position: ``pan:`` of a source route with two inputs (docs/follow.md).

Each input's level is measured as the route's tracker measures the mix (vibration mode: the
paper's 80-200 Hz band; audio mode: BS.1770's K-weighting), over the tracker's balance window
(``balance_ms``, 100 ms: a level difference is a balance; 100 ms of 80-200 Hz noise holds about
24 degrees of freedom, so two uncorrelated noises of one level differ by 1.5 dB rms, 6 % of the
default 24 dB span; K-weighted program audio by 0.1-0.2 dB). The level difference ``d = L - R``
(dB) puts the source at

``u = 0.5 - d / (2 range_db)``, clipped to [0, 1], ``position = left + u (right - left)``:

only the first input -> ``left``, equal levels -> the middle, only the second -> ``right``. A
constant-power pan law (``L = cos a``, ``R = sin a``) gives a ``u`` monotonic in ``a``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.follow import TrackerParams
from vibsynth.dsp.follow.loudness import k_weighting_sos
from vibsynth.dsp.follow.stream import BoxcarAtEnds, SosStream
from vibsynth.dsp.follow.vibration import intensity_sos
from vibsynth.settings.models_follow import FollowPan

__all__ = ["StereoPan", "pan_fraction", "Position"]

Position = tuple[float, float, float]


def pan_fraction(difference_db: float, range_db: float) -> float:
    """Where between ``left`` (0) and ``right`` (1) a level difference ``L - R`` (dB) puts the source."""
    if math.isnan(difference_db):
        return 0.5
    return min(1.0, max(0.0, 0.5 - difference_db / (2.0 * range_db)))


def _point(values: Sequence[float]) -> NDArray[np.float64]:
    return np.array([*values, 0.0][:3], dtype=np.float64)


class StereoPan:
    """The pan of a two-channel input, block by block (causal, bounded memory).

    Parameters
    ----------
    fs : float
        Input rate (Hz).
    params : TrackerParams
        The route's tracker parameters: ``mode`` picks the level filter, ``balance_ms`` the window.
    pan : FollowPan
        The two points and the range.
    """

    def __init__(self, fs: float, params: TrackerParams, pan: FollowPan) -> None:
        self.fs = float(fs)
        self.pan = pan
        self.left, self.right = _point(pan.left), _point(pan.right)
        sos = intensity_sos(self.fs) if params.mode == "vibration" else k_weighting_sos(self.fs)
        self._filters = (SosStream(sos), SosStream(sos))
        self._box = BoxcarAtEnds(max(1, int(round(params.balance_ms * 1e-3 * self.fs))), channels=2)
        #: the last fraction (0 = left, 1 = right) and level difference (dB)
        self.fraction = 0.5
        self.difference_db = 0.0

    def reset(self) -> None:
        """Forget the signal (filters and window); the last position is kept."""
        for f in self._filters:
            f.reset()
        self._box.reset()

    def process(self, x: NDArray[np.float32] | NDArray[np.float64]) -> float:
        """Take a block, shape (n, 2), and return the fraction (0 = left .. 1 = right) at its end.

        Silence on both inputs keeps the last fraction (a source does not jump to the middle in a pause).
        """
        if x.shape[0] == 0:
            return self.fraction
        block = np.nan_to_num(np.asarray(x, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        bands = np.stack([f(block[:, i]) for i, f in enumerate(self._filters)])
        power = self._box(bands * bands, np.array([block.shape[0]], dtype=np.intp))[:, 0]
        left, right = float(power[0]), float(power[1])
        if left + right <= 1e-30:
            return self.fraction
        with np.errstate(divide="ignore"):
            self.difference_db = float(10.0 * (np.log10(left) - np.log10(right)))
        self.fraction = pan_fraction(self.difference_db, self.pan.range_db)
        return self.fraction

    def position(self, fraction: float | None = None) -> Position:
        """The point at ``fraction`` (default: the last) between ``left`` and ``right``, (x, y, z) in metres."""
        u = self.fraction if fraction is None else fraction
        p = self.left + u * (self.right - self.left)
        return (float(p[0]), float(p[1]), float(p[2]))
