"""Rational resampling block by block, equal to ``scipy.signal.resample_poly`` on the whole signal.

:class:`StreamResampler` takes blocks of any length and returns the output frames they
complete. Each piece is resampled with ``resample_poly`` together with ``context`` input frames
on either side (more than the filter's half length) and only its middle is kept; pieces start on
multiples of ``down`` input frames, so every output frame is computed exactly as the one-shot
call computes it, with the same zeros before the first input frame and after the last
(:meth:`StreamResampler.flush`). Memory: a few blocks, whatever the signal's length. Latency:
``context`` input frames.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import ParameterError

__all__ = ["StreamResampler"]

#: resample_poly's default filter half length, in up-sampled samples per max(up, down).
_HALF_LEN_PER_FACTOR = 10


class StreamResampler:
    """Resample (frames, channels) blocks from ``fs_in`` to ``fs_out`` (see the module notes).

    Parameters
    ----------
    fs_in, fs_out : float
        Rates (Hz) whose ratio is a fraction with terms up to 10**6.
    channels : int
    piece : int
        Input frames resampled per call of ``resample_poly`` (rounded up to a multiple of ``down``).

    Attributes
    ----------
    up, down : int
        The reduced ratio fs_out / fs_in.
    context : int
        Input frames of look-ahead (the latency) and look-behind of each piece.
    """

    def __init__(self, fs_in: float, fs_out: float, channels: int, *, piece: int = 4096) -> None:
        if not (math.isfinite(fs_in) and math.isfinite(fs_out) and fs_in > 0 and fs_out > 0):
            raise ParameterError(f"resampling needs finite rates > 0, got {fs_in!r} -> {fs_out!r} Hz")
        ratio = Fraction(fs_out / fs_in).limit_denominator(1_000_000)
        if abs(float(ratio) - fs_out / fs_in) > 1e-9 * fs_out / fs_in:
            raise ParameterError(f"{fs_in:g} -> {fs_out:g} Hz is not a ratio of integers up to 10**6")
        if int(channels) != channels or channels < 1:
            raise ParameterError(f"channels must be >= 1, got {channels!r}")
        self.up, self.down = ratio.numerator, ratio.denominator
        self.channels = int(channels)
        half = _HALF_LEN_PER_FACTOR * max(self.up, self.down)
        self.context = self._multiple(-(-half // self.up) + 1)
        self.piece = self._multiple(max(int(piece), 1))
        # input frames from (piece start - context) on; zeros stand before the first frame
        self._pending = np.zeros((self.context, self.channels), dtype=np.float64)
        self._taken = 0  # input frames given
        self._done = 0  # input frames whose output has been returned
        self._given_out = 0  # output frames returned

    def _multiple(self, n: int) -> int:
        return -(-int(n) // self.down) * self.down

    @property
    def identity(self) -> bool:
        return self.up == self.down == 1

    def process(self, block: NDArray[np.floating]) -> NDArray[np.float64]:
        """Take input frames (n, channels); return the output frames completed so far (m, channels)."""
        x = np.asarray(block, dtype=np.float64).reshape(-1, self.channels)
        self._taken += x.shape[0]
        if self.identity:
            self._done = self._taken
            self._given_out += x.shape[0]
            return np.array(x, dtype=np.float64)
        self._pending = np.concatenate([self._pending, x])
        out = []
        while self._pending.shape[0] >= self.context + self.piece + self.context:
            out.append(self._run(self.piece))
        return np.concatenate(out) if out else np.zeros((0, self.channels))

    def flush(self) -> NDArray[np.float64]:
        """The last output frames (the input ended): ``ceil(frames_in * up / down)`` in all."""
        total = -(-self._taken * self.up // self.down)
        if self.identity:
            return np.zeros((0, self.channels))
        out = []
        while self._given_out < total:
            rest = self._pending.shape[0] - self.context  # real frames not yet resampled (may be <= 0)
            n = self._multiple(max(min(rest, self.piece), 1))
            need = self.context + n + self.context - self._pending.shape[0]
            if need > 0:
                self._pending = np.concatenate([self._pending, np.zeros((need, self.channels))])
            y = self._run(n)
            out.append(y[: total - self._given_out + y.shape[0]])
        return np.concatenate(out) if out else np.zeros((0, self.channels))

    def _run(self, n: int) -> NDArray[np.float64]:
        from scipy.signal import resample_poly

        c = self.context
        seg = self._pending[: c + n + c]
        y = resample_poly(seg, self.up, self.down, axis=0)
        first = c * self.up // self.down
        count = n * self.up // self.down
        self._pending = self._pending[n:]
        self._done += n
        self._given_out += count
        return np.asarray(y[first : first + count], dtype=np.float64)
