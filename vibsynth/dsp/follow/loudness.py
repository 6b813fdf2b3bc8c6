"""ITU-R BS.1770-4 loudness: the K-weighting filter and integrated (gated) loudness in LUFS.

Written here (two biquads and the standard's gating) rather than taken from pyloudnorm: the
tracker needs the K-weighting as a streaming filter at any rate, and the integrated measure is
the same twenty lines around it. Multichannel input sums the channels' powers with weight 1
(the standard's weights for L, R, C; surround weights of 1.41 are not applied).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from vibsynth.errors import ParameterError

__all__ = ["k_weighting_sos", "integrated_loudness", "ABSOLUTE_GATE_LUFS"]

ABSOLUTE_GATE_LUFS = -70.0
_BLOCK_S = 0.4
_STEP_S = 0.1


def k_weighting_sos(fs: float) -> NDArray[np.float64]:
    """ITU-R BS.1770-4 K-weighting at any rate (the shelf and high-pass of the standard, from their
    analog prototypes; at 48 kHz the coefficients equal the standard's table).

    Returns
    -------
    sos : ndarray, shape (2, 6)
    """
    # Stage 1: high shelf (f0 1681.97 Hz, gain 3.99984 dB, Q 0.70717).
    f0, gain, q = 1681.974450955533, 3.999843853973347, 0.7071752369554196
    k = math.tan(math.pi * f0 / fs)
    vh = 10.0 ** (gain / 20.0)
    vb = vh**0.4996667741545416
    a0 = 1.0 + k / q + k * k
    shelf = [(vh + vb * k / q + k * k) / a0, 2.0 * (k * k - vh) / a0, (vh - vb * k / q + k * k) / a0]
    shelf_a = [1.0, 2.0 * (k * k - 1.0) / a0, (1.0 - k / q + k * k) / a0]
    # Stage 2: high-pass (f0 38.14 Hz, Q 0.50033).
    f0, q = 38.13547087602444, 0.5003270373238773
    k = math.tan(math.pi * f0 / fs)
    a0 = 1.0 + k / q + k * k
    hp_a = [1.0, 2.0 * (k * k - 1.0) / a0, (1.0 - k / q + k * k) / a0]
    hp = [1.0, -2.0, 1.0]
    return np.array([shelf + shelf_a, hp + hp_a], dtype=np.float64)


def integrated_loudness(x: ArrayLike, fs: float) -> float:
    """Integrated loudness (LUFS) of a signal, BS.1770-4 (400 ms blocks, 75 % overlap, -70 LUFS
    absolute and -10 LU relative gates).

    Parameters
    ----------
    x : array_like, shape (n,) or (n, channels)
    fs : float

    Returns
    -------
    loudness : float
        ``-inf`` when every block is below the absolute gate.

    Raises
    ------
    ParameterError
        Shorter than one 400 ms block, non-finite samples or a bad rate.
    """
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, np.newaxis]
    if arr.ndim != 2 or not math.isfinite(fs) or fs < 8000:
        raise ParameterError(f"loudness needs (n,) or (n, channels) samples at >= 8 kHz, got {arr.shape} at {fs}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError("loudness: the signal has NaN or infinite samples")
    block, step = int(round(_BLOCK_S * fs)), int(round(_STEP_S * fs))
    if arr.shape[0] < block:
        raise ParameterError(f"loudness needs at least {_BLOCK_S:g} s, got {arr.shape[0] / fs:.3f} s")
    k = signal.sosfilt(k_weighting_sos(fs), arr, axis=0)
    power = (k * k).sum(axis=1)
    cum = np.concatenate(([0.0], np.cumsum(power)))
    starts = np.arange(0, arr.shape[0] - block + 1, step)
    z = (cum[starts + block] - cum[starts]) / block
    with np.errstate(divide="ignore"):
        lk = -0.691 + 10.0 * np.log10(z)
    z = z[lk > ABSOLUTE_GATE_LUFS]
    if z.size == 0:
        return -math.inf
    relative = -0.691 + 10.0 * math.log10(float(z.mean())) - 10.0
    z = z[-0.691 + 10.0 * np.log10(z) > relative]
    return float(-0.691 + 10.0 * math.log10(float(z.mean())))
