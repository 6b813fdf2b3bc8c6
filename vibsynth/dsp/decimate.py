"""Block-by-block decimation of high-rate input (176.4, 192, 384 kHz) to an ordinary rate.

The follow tracker looks at 80-200 Hz levels and the spectral balance below ~1 kHz (vibration
mode) or program audio's loudness and brightness (audio mode): nothing above 20 kHz matters,
and a 192 kHz file costs four times the analysis of a 48 kHz one. :class:`BlockDecimator`
low-pass filters (an 8th-order Butterworth at 0.9 x the new Nyquist frequency, as
second-order sections whose state carries across blocks) and keeps every ``factor``-th
sample, so the output of a stream cut into any blocks is the output of the whole signal.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import ParameterError

__all__ = ["BlockDecimator", "decimation_factor", "MAX_ANALYSIS_RATE"]

#: Rates above this are decimated; at or below it the input is taken as it is.
MAX_ANALYSIS_RATE = 96_000.0


def decimation_factor(fs: float, max_rate: float = MAX_ANALYSIS_RATE) -> int:
    """The smallest integer factor that brings ``fs`` to at most ``max_rate`` (1 when it already is)."""
    if not math.isfinite(fs) or fs <= 0:
        raise ParameterError(f"sample rate must be positive, got {fs!r}")
    return max(1, math.ceil(fs / max_rate - 1e-9))


class BlockDecimator:
    """Decimate a stream of mono blocks by an integer factor.

    Parameters
    ----------
    fs : float
        Input rate (Hz).
    max_rate : float
        Output rate ceiling: the factor is :func:`decimation_factor` (``fs`` 192 kHz -> 4 ->
        48 kHz; 176.4 kHz -> 2 -> 88.2 kHz).

    Attributes
    ----------
    factor : int
    fs_out : float
        ``fs / factor``.
    """

    def __init__(self, fs: float, max_rate: float = MAX_ANALYSIS_RATE) -> None:
        from scipy.signal import butter, sosfilt_zi

        self.factor = decimation_factor(fs, max_rate)
        self.fs_in = float(fs)
        self.fs_out = self.fs_in / self.factor
        self._sos: NDArray[np.float64] | None = None
        self._zi: NDArray[np.float64] | None = None
        if self.factor > 1:
            self._sos = np.asarray(butter(8, 0.9 / self.factor, output="sos"), dtype=np.float64)
            self._zi = np.zeros_like(np.asarray(sosfilt_zi(self._sos)))
        self._phase = 0  # input samples to skip before the next kept one

    def process(self, block: NDArray[np.floating]) -> NDArray[np.float64]:
        """Decimate one block.

        Parameters
        ----------
        block : ndarray, shape (n,)

        Returns
        -------
        out : ndarray, float64, shape (m,)
            The kept samples (about ``n / factor``; a block shorter than the factor may give none).
        """
        x = np.asarray(block, dtype=np.float64).reshape(-1)
        if self.factor == 1:
            return x
        from scipy.signal import sosfilt

        y, self._zi = sosfilt(self._sos, x, zi=self._zi)
        out = np.asarray(y[self._phase :: self.factor], dtype=np.float64)
        self._phase = (self._phase - x.size) % self.factor
        return out
