"""Streaming building blocks: stateful IIR filtering, decimation and windows over the recent past.

Every object keeps bounded state (filter states, at most one window of samples) and gives the
same output whatever the block sizes are, so the tracker is identical offline and live.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from vibsynth.errors import ParameterError

try:  # SciPy's compiled kernel behind sosfilt: the public wrapper's checks cost ~40 us per call,
    # 20 times the filtering of a live block, and the bank makes 30 calls per chunk.
    from scipy.signal._sosfilt import _sosfilt as _sosfilt_kernel
except ImportError:  # pragma: no cover - other SciPy layouts
    _sosfilt_kernel = None

__all__ = ["SosStream", "Resampler", "BoxcarAtEnds", "HopSums", "Ring", "rate_factors", "group_delay_s"]


class SosStream:
    """A causal second-order-sections filter that keeps its state between blocks.

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    """

    def __init__(self, sos: NDArray[np.float64]) -> None:
        self.sos = np.ascontiguousarray(sos, dtype=np.float64)
        self.zi: NDArray[np.float64] | None = None

    def reset(self) -> None:
        self.zi = None

    def __call__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Filter one block, shape (n,) -> (n,), starting from rest."""
        if x.size == 0:
            return np.zeros(0)
        if self.zi is None:
            self.zi = np.zeros((1, self.sos.shape[0], 2))
        if _sosfilt_kernel is not None:
            y = np.array(x, dtype=np.float64, order="C", ndmin=2)  # a copy: the kernel filters in place
            _sosfilt_kernel(self.sos, y, self.zi)
            return np.asarray(y[0], dtype=np.float64)
        out, zi = signal.sosfilt(self.sos, x, zi=self.zi[0])
        self.zi = np.ascontiguousarray(zi)[np.newaxis]
        return np.asarray(out, dtype=np.float64)


def rate_factors(fs: float, target_hz: float) -> tuple[int, int]:
    """``(up, down)``: the largest whole decimation that keeps the rate at or above ``target_hz``,
    or the smallest whole interpolation that reaches it."""
    if fs >= target_hz:
        return 1, max(1, int(math.floor(fs / target_hz + 1e-9)))
    return int(math.ceil(target_hz / fs - 1e-9)), 1


def group_delay_s(sos: NDArray[np.float64], freq_hz: float, fs: float) -> float:
    """Group delay (s) of a filter at one frequency."""
    total = 0.0
    for section in np.atleast_2d(sos):
        _, gd = signal.group_delay((section[:3], section[3:]), w=[freq_hz], fs=fs)
        total += float(gd[0])
    return total / fs


class Resampler:
    """Change the rate by a whole factor up or down, across blocks (causal elliptic filters).

    Parameters
    ----------
    fs : float
        Input rate (Hz).
    up, down : int
        Output rate ``fs * up / down``; one of them is 1. ``up = down = 1`` passes samples through.
    passband_hz : float
        Highest frequency that must pass (0.1 dB ripple, 70 dB stop band from the lower Nyquist up).
    """

    def __init__(self, fs: float, up: int, down: int, passband_hz: float) -> None:
        self.up, self.down = int(up), int(down)
        if self.up > 1 and self.down > 1:
            raise ParameterError("a resampler goes up or down, not both")
        self.fs_out = fs * self.up / self.down
        self._phase = 0  # input samples to skip before the next kept one (down)
        self.filter: SosStream | None = None
        self._filter_fs = fs * self.up
        if self.up > 1 or self.down > 1:
            stop = 0.5 * min(fs, self.fs_out)
            if not passband_hz < stop:
                raise ParameterError(f"resampling {fs:g} -> {self.fs_out:g} Hz cannot pass {passband_hz:g} Hz")
            order, wn = signal.ellipord(passband_hz, stop, 0.1, 70.0, fs=self._filter_fs)
            self.filter = SosStream(signal.ellip(order, 0.1, 70.0, wn, btype="low", output="sos", fs=self._filter_fs))

    def reset(self) -> None:
        self._phase = 0
        if self.filter is not None:
            self.filter.reset()

    def delay_s(self, freq_hz: float) -> float:
        """Group delay of the anti-alias / anti-image filter at ``freq_hz``."""
        return 0.0 if self.filter is None else group_delay_s(self.filter.sos, freq_hz, self._filter_fs)

    def __call__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.filter is None:
            return x
        if self.up > 1:
            stuffed = np.zeros(x.size * self.up)
            stuffed[:: self.up] = x * self.up
            return self.filter(stuffed)
        y = self.filter(x)
        kept = y[self._phase :: self.down]
        self._phase = (self._phase - x.size) % self.down
        return kept


class BoxcarAtEnds:
    """Mean of a per-sample quantity over the last ``window`` samples, evaluated at chosen ends.

    Keeps the last ``window`` values (bounded memory). Sums are local to one block plus that
    history, so precision does not degrade over an hour of input.

    Parameters
    ----------
    window : int
        Samples (>= 1).
    channels : int
        Parallel series (rows).
    """

    def __init__(self, window: int, channels: int = 1) -> None:
        if window < 1:
            raise ParameterError(f"window must be >= 1 sample, got {window}")
        self.window = int(window)
        self.channels = int(channels)
        self._tail = np.zeros((self.channels, self.window))
        self._filled = 0

    def reset(self) -> None:
        self._tail[:] = 0.0
        self._filled = 0

    def __call__(self, values: NDArray[np.float64], ends: NDArray[np.intp]) -> NDArray[np.float64]:
        """Append ``values`` (channels, n) and return the means ending at each of ``ends``.

        Parameters
        ----------
        values : ndarray, shape (channels, n)
        ends : ndarray of int, shape (k,)
            Exclusive end indices into this block, 1..n.

        Returns
        -------
        means : ndarray, shape (channels, k)
            Over the samples available so far when fewer than ``window`` have arrived.
        """
        w = self.window
        joined = np.concatenate((self._tail, values), axis=1)
        cum = np.concatenate((np.zeros((self.channels, 1)), np.cumsum(joined, axis=1)), axis=1)
        stop = ends + w
        means = (cum[:, stop] - cum[:, stop - w]) / np.maximum(1, np.minimum(w, self._filled + ends))
        self._tail = joined[:, -w:]
        self._filled = min(w, self._filled + values.shape[1])
        return np.asarray(means, dtype=np.float64)


class HopSums:
    """Sums of a per-sample quantity over consecutive hops whose ends fall in the current block.

    The partial sum of an unfinished hop carries over to the next block.

    Parameters
    ----------
    channels : int
    """

    def __init__(self, channels: int = 1) -> None:
        self.channels = int(channels)
        self._carry = np.zeros(self.channels)

    def reset(self) -> None:
        self._carry[:] = 0.0

    def __call__(self, values: NDArray[np.float64], ends: NDArray[np.intp]) -> NDArray[np.float64]:
        """Sums over each hop ending at ``ends`` (exclusive indices into this block), shape (channels, k)."""
        n = values.shape[1]
        cum = np.concatenate((np.zeros((self.channels, 1)), np.cumsum(values, axis=1)), axis=1)
        starts = np.concatenate(([0], ends[:-1])).astype(np.intp)
        sums = cum[:, ends] - cum[:, starts]
        if ends.size:
            sums[:, 0] += self._carry
            self._carry = cum[:, n] - cum[:, ends[-1]]
        else:
            self._carry = self._carry + cum[:, n]
        return np.asarray(sums, dtype=np.float64)


class Ring:
    """The last ``size`` rows of a stream of vectors (oldest first when read).

    Parameters
    ----------
    size : int
    width : int
    """

    def __init__(self, size: int, width: int) -> None:
        self.size = int(size)
        self._data = np.zeros((self.size, int(width)))
        self._pos = 0
        self.count = 0

    def reset(self) -> None:
        self._data[:] = 0.0
        self._pos = 0
        self.count = 0

    def push(self, row: NDArray[np.float64]) -> None:
        self._data[self._pos] = row
        self._pos = (self._pos + 1) % self.size
        self.count += 1

    def last(self, n: int) -> NDArray[np.float64]:
        """The newest ``min(n, available)`` rows, oldest first, shape (m, width)."""
        m = min(int(n), self.size, self.count)
        idx = (self._pos - m + np.arange(m)) % self.size
        return self._data[idx]
