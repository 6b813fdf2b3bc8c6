"""Vibration mode: the paper's model, causal, per window.

Intensity
    The 80-200 Hz band level: the paper's 2nd-order Butterworth band-pass (4 poles, as
    :mod:`vibsynth.dsp.intensity` defines it), here as a causal digital filter with pre-warped
    edges, squared and averaged over the last ``level_ms`` (default 10 ms: real scans move
    2-3 dB in 50 ms). At gain 0 the output is asked for exactly this band level.
Balance
    t1 of the 30-band log spectrum on the basis' V1 (the paper's balance): each band of
    :mod:`vibsynth.dsp.filterbank` as a causal Butterworth band-pass, its power averaged over the
    last ``balance_ms`` (the paper's 100 ms). A band narrower than about 20 Hz holds fewer than
    2 degrees of freedom in 100 ms (the 10 Hz band: 0.35), which makes its dB both noisy and
    biased (the codec's "+4 t1" bias); such bands average over the shortest window that gives
    them :data:`MIN_DOF` (the 10 Hz band: 0.5 s), and every band's dB is corrected by the known
    mean of the log of a chi-square with that many degrees of freedom, so stationary noise
    measures an unbiased t1. (4 degrees of freedom, 0.75 s for the 10 Hz band, lagged 0.44
    balance behind a seam between two HaTT textures in a 0.5 s window; 2 keep it under 0.3 and
    stationary noise within 0.1.)
    Each band's power is divided by the broadband power over the same window, delayed by the
    band's filter delay, so a level step does not read as a change of balance while the narrow
    bands catch up (a 15 dB step swung the balance by 0.5 for 200 ms without it).
Onsets
    Rises of the broadband (20 Hz high-passed) power (:mod:`vibsynth.dsp.follow.onsets`).

The bank runs on chunks of about 25 ms (a whole number of hops), which costs 30 short filter
calls per chunk instead of per block; each frame carries the balance of the last finished
chunk (a hold of at most 25 ms under a 100 ms window).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import signal, special

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.filterbank import EDGE_RATIO
from vibsynth.dsp.follow.onsets import OnsetDetector
from vibsynth.dsp.follow.stream import BoxcarAtEnds, HopSums, Ring, SosStream, group_delay_s
from vibsynth.dsp.intensity import BUTTERWORTH_ORDER, INTENSITY_BAND_HZ

__all__ = ["VIBRATION_RATE_HZ", "LevelMeter", "VibrationAnalyzer", "MIN_DOF", "band_sos", "intensity_sos"]

#: Internal rate of vibration mode: the input is decimated (or interpolated) by a whole factor to
#: at least this. The causal filters' bilinear warping at 1 kHz stays under 0.25 dB here; at 4 kHz
#: the 80-200 Hz filter's upper skirt lost up to 1.3 dB of a bright spectrum's band level.
VIBRATION_RATE_HZ = 8000.0
#: Degrees of freedom each band's power estimate has at least (sets the low bands' windows).
MIN_DOF = 2.0
_CHUNK_S = 0.025
_MAX_BAND_WINDOW_S = 3.0
_LN10 = math.log(10.0)


def intensity_sos(fs: float) -> NDArray[np.float64]:
    """The paper's 80-200 Hz 2nd-order Butterworth band-pass as causal sections at ``fs``."""
    return np.asarray(
        signal.butter(BUTTERWORTH_ORDER, INTENSITY_BAND_HZ, btype="bandpass", output="sos", fs=fs), dtype=np.float64
    )


def band_sos(centre_hz: float, fs: float, order: int) -> NDArray[np.float64]:
    """One perceptual band (edges at the geometric midpoints) as causal sections at ``fs``."""
    lo, hi = centre_hz / EDGE_RATIO, min(centre_hz * EDGE_RATIO, 0.49 * fs)
    return np.asarray(signal.butter(order, (lo, hi), btype="bandpass", output="sos", fs=fs), dtype=np.float64)


def _dof(sos: NDArray[np.float64], window: int, fs: float) -> float:
    """Degrees of freedom of a ``window``-sample mean of the squared output, for white Gaussian input."""
    n = int(min(20 * fs, max(8 * window, 4 * fs)))
    impulse = np.zeros(n)
    impulse[0] = 1.0
    h = signal.sosfilt(sos, impulse)
    spec = np.fft.rfft(h, 2 * n)
    r = np.fft.irfft(np.abs(spec) ** 2)[: min(window, n)]  # autocorrelation, lags 0..window-1
    lags = np.arange(r.size)
    var_sum = r[0] ** 2 * window + 2.0 * float(np.sum((window - lags[1:]) * r[1:] ** 2))
    return float(window**2 * r[0] ** 2 / var_sum)


def _log_chi2_bias_db(dof: float) -> float:
    """Mean of ``10 log10(chi2_dof / dof)``: how far below the true power the dB estimate lies."""
    return float(10.0 / _LN10 * (special.digamma(dof / 2.0) - math.log(dof / 2.0)))


class LevelMeter:
    """The paper's 80-200 Hz band level over a boxcar window, causal, at one rate.

    Parameters
    ----------
    fs : float
    level_ms : float
        Window length.
    """

    def __init__(self, fs: float, level_ms: float) -> None:
        self.filter = SosStream(intensity_sos(fs))
        self.window = max(1, int(round(level_ms * 1e-3 * fs)))
        self._box = BoxcarAtEnds(self.window)
        #: group delay of the filter at the band's centre (s)
        self.delay_s = group_delay_s(self.filter.sos, math.sqrt(INTENSITY_BAND_HZ[0] * INTENSITY_BAND_HZ[1]), fs)

    def reset(self) -> None:
        self.filter.reset()
        self._box.reset()

    def __call__(self, x: NDArray[np.float64], ends: NDArray[np.intp]) -> NDArray[np.float64]:
        """Band level (dB, ``-inf`` for silence) of the windows ending at ``ends`` in this block."""
        band = self.filter(x)
        power = self._box((band * band)[np.newaxis, :], ends)[0]
        with np.errstate(divide="ignore"):
            return np.asarray(10.0 * np.log10(power), dtype=np.float64)


class VibrationAnalyzer:
    """Per-frame band level, balance and onset function of a vibration at the internal rate.

    Parameters
    ----------
    fs : float
        Internal rate (Hz, >= 2.4 kHz).
    hop : int
        Samples per frame at ``fs``.
    basis : Basis
    level_ms, balance_ms : float
    balance_limits : tuple of float
        The balance is clamped to this live range.
    uniform_windows : bool
        Every band over ``balance_ms`` with no bias correction (the codec's windows: it pools
        windows into segments itself).
    """

    def __init__(
        self,
        *,
        fs: float,
        hop: int,
        basis: Basis,
        level_ms: float,
        balance_ms: float,
        balance_limits: tuple[float, float],
        uniform_windows: bool = False,
    ) -> None:
        self.fs = float(fs)
        self.hop = int(hop)
        self.basis = basis
        self.balance_limits = balance_limits
        self.meter = LevelMeter(fs, level_ms)
        #: off when the tracker measures the level at the input rate itself
        self.measure_level = True
        self.level_window = self.meter.window
        self.chunk_hops = max(1, int(round(_CHUNK_S * fs / self.hop)))
        if uniform_windows:
            self.chunk_hops = 1
        self.chunk = self.chunk_hops * self.hop
        sos = [band_sos(float(c), fs, basis.filter_order) for c in basis.centres_hz]
        self.bands = [SosStream(s) for s in sos]
        base = max(1, int(round(balance_ms * 1e-3 * fs / self.chunk)))
        self.band_chunks = np.full(len(sos), base, dtype=np.intp)
        self.bias_db = np.zeros(len(sos))
        if not uniform_windows:
            limit = max(base, int(round(_MAX_BAND_WINDOW_S * fs / self.chunk)))
            for k, s in enumerate(sos):
                n = base
                while n < limit and _dof(s, n * self.chunk, fs) < MIN_DOF:
                    n = min(limit, int(math.ceil(n * 1.25)))
                self.band_chunks[k] = n
                self.bias_db[k] = _log_chi2_bias_db(_dof(s, n * self.chunk, fs))
        # Level-change robustness: each band's power is divided by the broadband power averaged over
        # the same chunks, delayed by the band's own filter delay (whole chunks). A level step then
        # reaches numerator and denominator together, and the balance does not swing while the narrow
        # bands (up to 0.2 s of delay, 0.75 s of window) catch up with the wide ones.
        self.normalise = not uniform_windows
        self.band_lag = np.zeros(len(sos), dtype=np.intp)
        self._reference = SosStream(
            np.asarray(signal.butter(2, 8.0, btype="high", output="sos", fs=fs), dtype=np.float64)
        )
        self._chunks = Ring(int(self.band_chunks.max()), len(sos))
        self.band_delay_s = np.array([group_delay_s(sk, float(c), fs) for sk, c in zip(sos, basis.centres_hz)])
        if self.normalise:
            self.band_lag = np.round(self.band_delay_s * fs / self.chunk).astype(np.intp)
        self._broadband = Ring(int((self.band_chunks + self.band_lag).max()), 1)
        self._pending = np.zeros(0)
        self._balance = 0.0
        self._power = np.zeros(len(sos))
        self._band_db = np.full(len(sos), -np.inf)
        self._hp = SosStream(np.asarray(signal.butter(2, 20.0, btype="high", output="sos", fs=fs), dtype=np.float64))
        self._hop_power = HopSums()
        self.onsets = OnsetDetector(self.hop / self.fs, [1.0])
        #: group delay of the 80-200 Hz filter at its centre (s)
        self.filter_delay_s = self.meter.delay_s

    def reset(self) -> None:
        self.meter.reset()
        for b in self.bands:
            b.reset()
        self._chunks.reset()
        self._broadband.reset()
        self._reference.reset()
        self._pending = np.zeros(0)
        self._balance = 0.0
        self._power = np.zeros(len(self.bands))
        self._band_db[:] = -np.inf
        self._hp.reset()
        self._hop_power.reset()
        self.onsets.reset()

    @property
    def band_db(self) -> NDArray[np.float64]:
        """The newest 30-band spectrum (dB, bias corrected), shape (n_bands,)."""
        return np.array(self._band_db, dtype=np.float64)

    def _run_chunk(self, chunk: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        energy = np.array([float(np.sum(b(chunk) ** 2)) for b in self.bands])
        self._chunks.push(energy)
        rows = self._chunks.last(self._chunks.size)
        m = rows.shape[0]
        power = np.array([rows[max(0, m - n) :, k].mean() for k, n in enumerate(self.band_chunks)]) / self.chunk
        shape = power
        if self.normalise:
            self._broadband.push(np.array([float(np.sum(self._reference(chunk) ** 2))]))
            ref = self._broadband.last(self._broadband.size)[:, 0]
            r = ref.size
            mean = [
                ref[max(0, r - lag - n) : max(1, r - lag)].mean() for n, lag in zip(self.band_chunks, self.band_lag)
            ]
            with np.errstate(divide="ignore", invalid="ignore"):
                shape = power / np.array(mean)
        if np.all(shape > 0) and np.all(np.isfinite(shape)):
            self._band_db = 10.0 * np.log10(shape) - self.bias_db
            t1 = float(self.basis.scores(self._band_db)[0])
            lo, hi = self.balance_limits
            self._balance = float(np.clip(self.basis.balance_from_t1(t1), lo, hi))
        return self._balance, power

    def process(
        self, y: NDArray[np.float64], ends: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Analyse one block at the internal rate.

        Parameters
        ----------
        y : ndarray, shape (n,)
        ends : ndarray of int, shape (k,)
            Frame ends in this block (exclusive indices, increasing).

        Returns
        -------
        level_db, balance, rise_db, strength : ndarray, shape (k,)
            Band level (dB, ``-inf`` silent), balance knob, onset function, raw onset strength.
        band_power : ndarray, shape (k, n_bands)
            The 30-band powers behind each frame's balance (window means, not bias corrected).
        """
        level = self.meter(y, ends) if self.measure_level else np.zeros(ends.size)
        # The bank on whole chunks; a frame takes the balance of the last chunk ended at or before it.
        balance = np.empty(ends.size)
        bands = np.empty((ends.size, len(self.bands)))
        joined = np.concatenate((self._pending, y))
        offset = self._pending.size  # index of y[0] in joined
        done = 0
        j = 0
        while done + self.chunk <= joined.size:
            chunk_end = done + self.chunk - offset  # in y's indices
            while j < ends.size and ends[j] < chunk_end:
                balance[j] = self._balance
                bands[j] = self._power
                j += 1
            self._balance, self._power = self._run_chunk(joined[done : done + self.chunk])
            done += self.chunk
        balance[j:] = self._balance
        bands[j:] = self._power
        self._pending = joined[done:]
        hp = self._hp(y)
        hop_power = self._hop_power((hp * hp)[np.newaxis, :], ends) / self.hop
        rise, strength = self.onsets(hop_power, 1e-20)
        return level, balance, rise, strength, bands
