r"""Measuring an actuator's frequency response with exponential swept sines (Farina).

The stimulus is one recording-long buffer: a lead of silence (the noise floor), then
``n_sweeps`` identical exponential sweeps separated by silent gaps, then a tail. Played on
one output channel and recorded through a sensor (accelerometer, measurement microphone)
on one input, each sweep is deconvolved to an impulse response whose peak gives the loop's
latency and whose windowed spectrum gives the response (dB, *absolute*: recorded level per
unit of drive, through that sensor chain).

Why a sweep rather than noise
-----------------------------
An exponential sweep spends the same time in every octave, so its energy per octave is
constant where an actuator and the skin care most (10-200 Hz) instead of being spent above
1 kHz as white noise's is; its crest factor is 3 dB (a sine), so for a given peak it puts
several times more energy into the actuator than noise at the same peak; and the
deconvolution moves every harmonic distortion product to negative times (before the linear
impulse response), where the window discards it, so a slightly non-linear voice coil still
gives its linear response. Noise would need long averaging for the same SNR and mixes
distortion into the response. The price is that a sweep is sensitive to a burst of
background noise during the sweep; the repeatability check across sweeps catches that.

The sweep (Farina 2000), from ``f1`` to ``f2`` over ``T`` seconds, ``L = T / ln(f2 / f1)``:

.. math:: x(t) = \sin\left(2\pi f_1 L \left(e^{t/L} - 1\right)\right)

Its inverse filter is the time-reversed sweep with an envelope falling 6 dB per octave
(:func:`inverse_filter`); the deconvolution here divides spectra with a regularisation
outside ``[f1, f2]`` (:func:`deconvolve`), which gives the same impulse response with an
exact 0 dB gain in band. Everything here works on arrays (no I/O).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.filterbank import BAND_CENTRES_HZ, bandpass_response
from vibsynth.errors import ParameterError

__all__ = [
    "SweepPlan",
    "Measurement",
    "ResponseLoss",
    "RESPONSE_F_MIN_HZ",
    "RESPONSE_F_MAX_HZ",
    "CLIP_LEVEL",
    "response_freqs",
    "exp_sweep",
    "inverse_filter",
    "deconvolve",
    "band_limit",
    "ir_peak",
    "clipped_samples",
    "spectrum_db",
    "smooth_db",
    "combine_sweeps_db",
    "majority_spread_db",
    "band_response_db",
    "sweep_frequency",
    "response_loss",
    "measure_recording",
]

#: The response is reported from 10 to 1000 Hz (the synthesiser's band).
RESPONSE_F_MIN_HZ = 10.0
RESPONSE_F_MAX_HZ = 1000.0
#: Fine grid: 48 points per octave.
POINTS_PER_OCTAVE = 48
#: A sample at or above this (full scale 1) counts as clipped.
CLIP_LEVEL = 0.99
#: Magnitudes are smoothed over this fraction of an octave (power average).
SMOOTHING_OCTAVES = 1.0 / 24.0
#: Default impulse-response window after the peak (s): 0.5 s gives 2 Hz resolution and holds a
#: 10 Hz resonance's first cycles; 0.2 s before the peak keeps the band limit's zero-phase ringing
#: and stops short of the second harmonic's response (0.46 s earlier for the default sweep).
IR_WINDOW_S = 0.5
IR_PRE_S = 0.2
#: The level trace that finds a response lost mid-run (:func:`response_loss`): windows of this length (s),
LOSS_WINDOW_S = 0.02
#: a window this far (dB) above the lead silence's loudest windows (their 95th percentile) carries the sweep,
LOSS_ALIVE_DB = 10.0
#: one at most this far above them is silence,
LOSS_SILENT_DB = 3.0
#: and a loss needs at least this much (s) of the sweep that an earlier sweep brought back and this run did not.
LOSS_MIN_S = 0.25


def response_freqs(
    f_min: float = RESPONSE_F_MIN_HZ, f_max: float = RESPONSE_F_MAX_HZ, per_octave: int = POINTS_PER_OCTAVE
) -> NDArray[np.float64]:
    """The fine log-spaced grid of a measured response, shape (n,), ``f_min`` .. ``f_max`` included."""
    n = int(round(math.log2(f_max / f_min) * per_octave)) + 1
    return np.asarray(f_min * (f_max / f_min) ** (np.arange(n) / (n - 1)), dtype=np.float64)


def _check_band(fs: float, f1: float, f2: float, seconds: float) -> None:
    if not (math.isfinite(fs) and fs > 0):
        raise ParameterError(f"a sweep needs a sample rate > 0, got {fs!r}")
    if not (0 < f1 < f2 <= fs / 2):
        raise ParameterError(f"a sweep needs 0 < f1 < f2 <= fs/2, got {f1!r}..{f2!r} Hz at {fs:g} Hz")
    if not (math.isfinite(seconds) and 0.1 <= seconds <= 120):
        raise ParameterError(f"a sweep lasts 0.1..120 s, got {seconds!r}")


def exp_sweep(fs: float, f1: float, f2: float, seconds: float, *, fade_s: float = 0.05) -> NDArray[np.float64]:
    """Exponential sine sweep of peak 1, with raised-cosine fades at both ends.

    Parameters
    ----------
    fs : float
        Sample rate (Hz).
    f1, f2 : float
        Start and end frequency (Hz), ``0 < f1 < f2 <= fs/2``.
    seconds : float
        Duration.
    fade_s : float
        Fade-in/out length (s): the ends of a sweep click otherwise.

    Returns
    -------
    sweep : ndarray, shape (round(seconds * fs),)
    """
    _check_band(fs, f1, f2, seconds)
    n = int(round(seconds * fs))
    t = np.arange(n) / fs
    rate = seconds / math.log(f2 / f1)
    x = np.sin(2.0 * math.pi * f1 * rate * (np.exp(t / rate) - 1.0))
    k = min(int(round(fade_s * fs)), n // 4)
    if k > 0:
        ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(k) / k)
        x[:k] *= ramp
        x[n - k :] *= ramp[::-1]
    return np.asarray(x, dtype=np.float64)


def inverse_filter(sweep: ArrayLike, fs: float, f1: float, f2: float) -> NDArray[np.float64]:
    """Farina's inverse filter: the reversed sweep, falling 6 dB per octave, scaled to 0 dB gain.

    ``sweep * inverse`` (linear convolution) is a band-limited impulse at ``len(sweep) - 1``.

    Parameters
    ----------
    sweep : array_like, shape (n,)
        An :func:`exp_sweep` of ``f1`` .. ``f2``.
    fs, f1, f2 : float

    Returns
    -------
    inverse : ndarray, shape (n,)
    """
    x = np.asarray(sweep, dtype=np.float64)
    seconds = x.size / fs
    _check_band(fs, f1, f2, seconds)
    t = np.arange(x.size) / fs
    inv = x[::-1] * np.exp(-t * math.log(f2 / f1) / seconds)
    n = 1 << int(math.ceil(math.log2(2 * x.size)))
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    gain = np.abs(np.fft.rfft(x, n) * np.fft.rfft(inv, n))
    centre = math.sqrt(f1 * f2)
    ref = float(np.median(gain[(freqs > centre / 2) & (freqs < centre * 2)]))
    return np.asarray(inv / ref, dtype=np.float64)


def deconvolve(recording: ArrayLike, sweep: ArrayLike, fs: float, f1: float, f2: float) -> NDArray[np.float64]:
    """Impulse response of the system that turned ``sweep`` into ``recording``.

    A spectral division ``Y X* / (|X|^2 + eps)`` times :func:`band_limit`, so the response is
    exact in band (within 0.02 dB an octave inside ``[f1, f2]``) and nothing outside it is
    amplified.

    Parameters
    ----------
    recording : array_like, shape (m,)
        Index 0 = the instant the sweep's first sample was sent.
    sweep : array_like, shape (n,)
    fs, f1, f2 : float

    Returns
    -------
    ir : ndarray, shape (N,)
        ``N`` a power of two >= m + n; index ``k`` = a delay of ``k`` samples; distortion
        products and anything earlier than the sweep wrap to the end (negative times).
    """
    y = np.asarray(recording, dtype=np.float64)
    x = np.asarray(sweep, dtype=np.float64)
    n = 1 << int(math.ceil(math.log2(y.size + x.size)))
    X = np.fft.rfft(x, n)
    Y = np.fft.rfft(y, n)
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    power = np.abs(X) ** 2
    H = Y * np.conj(X) / (power + 1e-10 * float(np.max(power))) * band_limit(freqs, f1, f2)
    return np.asarray(np.fft.irfft(H, n), dtype=np.float64)


def band_limit(freqs: ArrayLike, f1: float, f2: float) -> NDArray[np.float64]:
    """The zero-phase band limit of a deconvolved response: 8th-order Butterworth magnitudes at ``f1`` and ``f2``.

    Smooth edges keep the impulse response short (a brick wall at ``f1`` rings for seconds);
    an octave inside the edges the gain is within 0.02 dB of 1.

    Parameters
    ----------
    freqs : array_like, shape (n,)
    f1, f2 : float

    Returns
    -------
    gain : ndarray, shape (n,)
    """
    f = np.asarray(freqs, dtype=np.float64)
    with np.errstate(divide="ignore"):
        low = (f1 / np.where(f > 0, f, 1e-12)) ** 8
    return np.asarray(1.0 / np.sqrt((1.0 + low) * (1.0 + (f / f2) ** 8)), dtype=np.float64)


def ir_peak(ir: ArrayLike, *, search: slice | None = None) -> float:
    """Position of an impulse response's largest magnitude, refined between samples.

    A parabola through the peak's magnitude and its neighbours gives the fraction of a
    sample; a pure delay of ``d`` samples returns ``d`` exactly.

    Parameters
    ----------
    ir : array_like, shape (N,)
    search : slice, optional
        Where to look (default everywhere).

    Returns
    -------
    position : float
        Samples from index 0.
    """
    h = np.abs(np.asarray(ir, dtype=np.float64))
    start = 0 if search is None or search.start is None else int(search.start)
    part = h if search is None else h[search]
    if part.size == 0:
        raise ParameterError("no samples to search for an impulse response peak")
    k = int(np.argmax(part))
    idx = start + k
    if 0 < k < part.size - 1:
        a, b, c = part[k - 1], part[k], part[k + 1]
        den = a - 2 * b + c
        if den < 0:
            return float(idx + 0.5 * (a - c) / den)
    return float(idx)


def clipped_samples(x: ArrayLike, level: float = CLIP_LEVEL) -> int:
    """Samples whose magnitude reaches ``level`` (a clipped input or converter)."""
    return int(np.count_nonzero(np.abs(np.asarray(x)) >= level))


def spectrum_db(
    ir: ArrayLike, fs: float, freqs: ArrayLike, *, smoothing_octaves: float = SMOOTHING_OCTAVES
) -> NDArray[np.float64]:
    """Magnitude (dB) of a windowed impulse response at ``freqs``, power-smoothed over a fraction of an octave.

    Parameters
    ----------
    ir : array_like, shape (L,)
        Already windowed.
    fs : float
    freqs : array_like, shape (n,)
        Hz, > 0.
    smoothing_octaves : float
        Width of the smoothing (0 = none: the nearest bin).

    Returns
    -------
    level_db : ndarray, shape (n,)
        ``10 log10`` of the mean power over ``f * 2**(+-w/2)`` (-400 dB for nothing).
    """
    h = np.asarray(ir, dtype=np.float64)
    f = np.asarray(freqs, dtype=np.float64)
    # Zero-padded so that the narrowest smoothing span (at the lowest frequency) holds 8 bins.
    f_low = max(float(f.min()), 1.0)
    span = f_low * (2.0 ** (smoothing_octaves / 2.0) - 2.0 ** (-smoothing_octaves / 2.0))
    n = max(h.size, int(8 * fs / span) if span > 0 else int(100 * fs / f_low))
    n = 1 << int(math.ceil(math.log2(min(n, 1 << 24))))
    bins = np.fft.rfftfreq(n, 1.0 / fs)
    power = np.abs(np.fft.rfft(h, n)) ** 2
    cum = np.concatenate([[0.0], np.cumsum(power)])
    half = 2.0 ** (smoothing_octaves / 2.0)
    lo = np.searchsorted(bins, f / half, side="left")
    hi = np.maximum(np.searchsorted(bins, f * half, side="right"), lo + 1)
    hi = np.minimum(hi, bins.size)
    lo = np.minimum(lo, hi - 1)
    mean = (cum[hi] - cum[lo]) / (hi - lo)
    return np.asarray(10.0 * np.log10(np.maximum(mean, 1e-40)), dtype=np.float64)


def smooth_db(values_db: ArrayLike) -> NDArray[np.float64]:
    """Power mean (dB) over the first axis: ``10 log10 mean 10^(v/10)``, shape of one row."""
    v = np.asarray(values_db, dtype=np.float64)
    return np.asarray(10.0 * np.log10(np.mean(10.0 ** (v / 10.0), axis=0)), dtype=np.float64)


def combine_sweeps_db(sweeps_db: ArrayLike) -> NDArray[np.float64]:
    """The response of several sweeps: their power mean for 1-2 sweeps, the median from 3 on.

    From three sweeps on, one sweep hit by a knock, a noise burst or a dropped block is
    outvoted at every frequency instead of pulling the mean.

    Parameters
    ----------
    sweeps_db : array_like, shape (n_sweeps, n)

    Returns
    -------
    response_db : ndarray, shape (n,)
    """
    v = np.asarray(sweeps_db, dtype=np.float64)
    if v.shape[0] >= 3:
        return np.asarray(np.median(v, axis=0), dtype=np.float64)
    return smooth_db(v)


def majority_spread_db(sweeps_db: ArrayLike) -> NDArray[np.float64]:
    """How far the sweeps that make the response agree, per frequency (dB).

    With ``n`` sweeps: the narrowest range holding ``n // 2 + 1`` of them (all of them for
    1-2 sweeps; two of three; three of four or five), so an outvoted sweep does not count.

    Parameters
    ----------
    sweeps_db : array_like, shape (n_sweeps, n)

    Returns
    -------
    spread_db : ndarray, shape (n,)
    """
    v = np.sort(np.asarray(sweeps_db, dtype=np.float64), axis=0)
    n = v.shape[0]
    k = n if n <= 2 else n // 2 + 1
    ranges = [v[i + k - 1] - v[i] for i in range(n - k + 1)]
    return np.asarray(np.min(np.stack(ranges), axis=0), dtype=np.float64)


def band_response_db(
    freqs: ArrayLike, level_db: ArrayLike, *, centres: ArrayLike = BAND_CENTRES_HZ
) -> NDArray[np.float64]:
    """A fine log-grid response averaged into the 30 perceptual bands (power, band-weighted).

    Parameters
    ----------
    freqs : array_like, shape (n,)
        The fine grid (log-spaced, as :func:`response_freqs`).
    level_db : array_like, shape (n,)
    centres : array_like, shape (n_bands,)

    Returns
    -------
    band_db : ndarray, shape (n_bands,)
    """
    weights = bandpass_response(np.asarray(freqs, dtype=np.float64), centres=centres)
    power = 10.0 ** (np.asarray(level_db, dtype=np.float64) / 10.0)
    return np.asarray(10.0 * np.log10((weights @ power) / weights.sum(axis=1)), dtype=np.float64)


@dataclass(frozen=True)
class SweepPlan:
    """The measurement stimulus: lead silence, ``n_sweeps`` sweeps with gaps, a tail.

    Attributes
    ----------
    fs : float
    f1, f2 : float
        Sweep range (Hz); the default reaches an octave beyond the reported 10-1000 Hz.
    seconds : float
        One sweep's duration.
    n_sweeps : int
        Sweeps played (repeatability; the response is their power mean).
    lead_s : float
        Silence before the first sweep (noise floor).
    gap_s : float
        Silence after each sweep (the impulse response's tail and the loop's latency).
    level : float
        Peak of the sweep (full scale 1).
    """

    fs: float
    f1: float = 5.0
    f2: float = 2000.0
    seconds: float = 4.0
    n_sweeps: int = 3
    lead_s: float = 1.0
    gap_s: float = 1.0
    level: float = 0.25

    def __post_init__(self) -> None:
        _check_band(self.fs, self.f1, self.f2, self.seconds)
        if int(self.n_sweeps) != self.n_sweeps or not 1 <= self.n_sweeps <= 20:
            raise ParameterError(f"sweeps must be 1..20, got {self.n_sweeps!r}")
        if not (0.5 <= self.lead_s <= 10 and 0.5 <= self.gap_s <= 10):
            raise ParameterError("lead and gap silences must be 0.5..10 s")
        if not (math.isfinite(self.level) and 0 < self.level <= 1):
            raise ParameterError(f"sweep level must be in (0, 1] of full scale, got {self.level!r}")

    @property
    def sweep_samples(self) -> int:
        return int(round(self.seconds * self.fs))

    @property
    def period(self) -> int:
        """Samples from one sweep's start to the next's."""
        return self.sweep_samples + int(round(self.gap_s * self.fs))

    @property
    def lead(self) -> int:
        return int(round(self.lead_s * self.fs))

    def sweep(self) -> NDArray[np.float64]:
        """One sweep of peak 1, shape (sweep_samples,)."""
        return exp_sweep(self.fs, self.f1, self.f2, self.seconds)

    def starts(self) -> list[int]:
        """Index of each sweep's first sample in :meth:`stimulus`."""
        return [self.lead + k * self.period for k in range(int(self.n_sweeps))]

    def stimulus(self) -> NDArray[np.float64]:
        """The whole buffer to play, at :attr:`level`, shape (lead + n_sweeps * period,)."""
        out = np.zeros(self.lead + int(self.n_sweeps) * self.period)
        sweep = self.level * self.sweep()
        for start in self.starts():
            out[start : start + sweep.size] = sweep
        return out


@dataclass(frozen=True)
class ResponseLoss:
    """Where a recording's response stopped and stayed at the noise floor (:func:`response_loss`).

    Times are into a sweep as it came back (after the loop's latency), to :data:`LOSS_WINDOW_S`.

    Attributes
    ----------
    sweep : int
        The sweep it was last heard in (1-based).
    seconds : float
        When it stopped: the end of the last window that carried it, into ``sweep``.
    freq_hz : float
        The sweep's instantaneous frequency at ``seconds``.
    missed_sweep : int
        The sweep of the first window that should have carried it (an earlier sweep's did) and was silent.
    missed_seconds : float
        That window's start, into ``missed_sweep``.
    missed_freq_hz : float
        The sweep's instantaneous frequency at ``missed_seconds``.
    """

    sweep: int
    seconds: float
    freq_hz: float
    missed_sweep: int
    missed_seconds: float
    missed_freq_hz: float

    @property
    def exact(self) -> bool:
        """True when the stop is known to two windows (else the sweep was too weak between the two points)."""
        return self.missed_sweep == self.sweep and self.missed_seconds - self.seconds <= 2.5 * LOSS_WINDOW_S


def sweep_frequency(plan: SweepPlan, seconds: ArrayLike) -> NDArray[np.float64]:
    """The instantaneous frequency (Hz) of the plan's exponential sweep ``seconds`` into it, same shape."""
    t = np.clip(np.asarray(seconds, dtype=np.float64), 0.0, plan.seconds)
    return np.asarray(plan.f1 * (plan.f2 / plan.f1) ** (t / plan.seconds), dtype=np.float64)


def _window_levels_db(x: NDArray[np.float64], win: int) -> NDArray[np.float64]:
    """RMS (dB) of consecutive ``win``-sample windows of ``x``, shape (len(x) // win,)."""
    n = x.size // win
    ms = np.mean(x[: n * win].reshape(n, win) ** 2, axis=1)
    return np.asarray(10.0 * np.log10(np.maximum(ms, 1e-30)), dtype=np.float64)


def response_loss(recording: ArrayLike, plan: SweepPlan, latency: float) -> ResponseLoss | None:
    """Where the response to the sweeps stopped and stayed at the noise floor, if it did.

    Each sweep's recording (from its start plus ``latency``) is cut into :data:`LOSS_WINDOW_S`
    windows and each window's RMS compared with the lead silence's: a window above the silence's
    loudest windows by :data:`LOSS_ALIVE_DB` carries the sweep, one within :data:`LOSS_SILENT_DB`
    of them is silence. The response was lost after the last window that carried the sweep when,
    from there on, the windows where some sweep carried it (so the actuator and sensor answer at
    that point of the sweep) are silent, at least 90 % of them and :data:`LOSS_MIN_S` worth. A
    response that is weak at the same point of every sweep (an actuator that does not reach 2 kHz)
    is no loss: no sweep carried it there.

    Parameters
    ----------
    recording : array_like, shape (m,)
        As for :func:`measure_recording`.
    plan : SweepPlan
    latency : float
        The loop's latency (samples), from the impulse response's peak.

    Returns
    -------
    loss : ResponseLoss or None
        None when the response never came back (no window carried the sweep) or never stopped.
    """
    y = np.asarray(recording, dtype=np.float64)
    win = max(1, int(round(LOSS_WINDOW_S * plan.fs)))
    n_w = plan.sweep_samples // win
    lag = max(0, int(round(latency)))
    lead = _window_levels_db(y[: plan.lead], win)
    if n_w == 0 or lead.size == 0:
        return None
    floor = float(np.percentile(lead, 95))
    rows = []
    for start in plan.starts():
        part = y[start + lag : start + lag + n_w * win]
        if part.size < n_w * win:
            return None
        rows.append(_window_levels_db(part, win))
    levels = np.stack(rows)  # (n_sweeps, n_w)
    carries = levels > floor + LOSS_ALIVE_DB
    if not np.any(carries):
        return None
    flat = carries.ravel()
    last = int(np.flatnonzero(flat)[-1])
    index = np.arange(flat.size)
    expected = (index > last) & np.tile(np.any(carries, axis=0), levels.shape[0])
    if np.count_nonzero(expected) * win < LOSS_MIN_S * plan.fs:
        return None
    silent = levels.ravel()[expected] <= floor + LOSS_SILENT_DB
    if np.mean(silent) < 0.9:
        return None
    sweep, w = divmod(last, n_w)
    missed_sweep, missed_w = divmod(int(np.flatnonzero(expected)[np.argmax(silent)]), n_w)
    seconds, missed_seconds = (w + 1) * win / plan.fs, missed_w * win / plan.fs
    return ResponseLoss(
        sweep=sweep + 1,
        seconds=seconds,
        freq_hz=float(sweep_frequency(plan, seconds)),
        missed_sweep=missed_sweep + 1,
        missed_seconds=missed_seconds,
        missed_freq_hz=float(sweep_frequency(plan, missed_seconds)),
    )


@dataclass(frozen=True)
class Measurement:
    """What one recording of a :class:`SweepPlan` tells.

    Attributes
    ----------
    freqs : ndarray, shape (n,)
        The fine grid (Hz).
    response_db : ndarray, shape (n,)
        Recorded level per unit of drive (dB; 0 dB = the input reads what the output sent):
        :func:`combine_sweeps_db` of the sweeps.
    sweeps_db : ndarray, shape (n_sweeps, n)
        Each sweep's response.
    noise_db : ndarray, shape (n,)
        The lead silence taken through the same deconvolution and window (the response's floor).
    snr_db : ndarray, shape (n,)
        ``response_db - noise_db``.
    band_db : ndarray, shape (30,)
        The response in the 30 perceptual bands.
    latency : float
        Samples from a sample's sending to its impulse-response peak (refined).
    peak : float
        Largest magnitude in the recording (full scale 1).
    noise_rms_db : float
        RMS of the lead silence (dBFS).
    signal_rms_db : float
        RMS of the recording during the first sweep (dBFS).
    clipped : int
        Samples at or above :data:`CLIP_LEVEL`.
    repeatability_db : float
        Largest :func:`majority_spread_db` where the SNR is at least ``min_snr_db``.
    loss : ResponseLoss or None
        Where the response stopped mid-run and stayed at the noise floor (:func:`response_loss`).
    """

    freqs: NDArray[np.float64]
    response_db: NDArray[np.float64]
    sweeps_db: NDArray[np.float64]
    noise_db: NDArray[np.float64]
    snr_db: NDArray[np.float64]
    band_db: NDArray[np.float64]
    latency: float
    peak: float
    noise_rms_db: float
    signal_rms_db: float
    clipped: int
    repeatability_db: float
    loss: ResponseLoss | None = None
    extra: dict[str, float] = field(default_factory=dict)

    def snr_in(self, f_lo: float, f_hi: float) -> float:
        """The lowest SNR (dB) between two frequencies."""
        sel = (self.freqs >= f_lo) & (self.freqs <= f_hi)
        return float(np.min(self.snr_db[sel]))


def _rms_db(x: NDArray[np.float64]) -> float:
    ms = float(np.mean(x * x)) if x.size else 0.0
    return 10.0 * math.log10(ms) if ms > 1e-30 else -300.0


def _window(n: int, pre: int) -> NDArray[np.float64]:
    """Flat, with a half-Hann fade over the last quarter and a fade-in over the first quarter of ``pre``."""
    w = np.ones(n)
    fade = n // 4
    w[n - fade :] = 0.5 + 0.5 * np.cos(np.pi * np.arange(fade) / fade)
    rise = pre // 4
    if rise > 0:
        w[:rise] = 0.5 - 0.5 * np.cos(np.pi * np.arange(rise) / rise)
    return w


def measure_recording(
    recording: ArrayLike,
    plan: SweepPlan,
    *,
    freqs: ArrayLike | None = None,
    ir_window_s: float = IR_WINDOW_S,
    min_snr_db: float = 20.0,
    max_latency_s: float = 0.5,
) -> Measurement:
    """Deconvolve each sweep of a recording of :meth:`SweepPlan.stimulus` into a response.

    Parameters
    ----------
    recording : array_like, shape (m,)
        The input, index 0 = the instant the stimulus' first sample was sent (the loop's own
        latency, up to ``max_latency_s``, is found from the impulse response's peak); ``m``
        at least the stimulus' length plus that latency.
    plan : SweepPlan
    freqs : array_like, shape (n,), optional
        Where to report the response (default :func:`response_freqs`).
    ir_window_s : float
        Impulse-response window after the peak (s).
    min_snr_db : float
        SNR from which a frequency counts in the repeatability.
    max_latency_s : float
        Longest loop latency searched for.

    Returns
    -------
    measurement : Measurement
    """
    y = np.asarray(recording, dtype=np.float64)
    fs = plan.fs
    f = response_freqs() if freqs is None else np.asarray(freqs, dtype=np.float64)
    max_lat = int(round(max_latency_s * fs))
    if not 0 < max_latency_s <= plan.gap_s / 2:
        raise ParameterError(
            f"the latency searched for must be in (0, gap/2 = {plan.gap_s / 2:g}] s, got {max_latency_s!r}"
        )
    need = plan.lead + (int(plan.n_sweeps) - 1) * plan.period + plan.sweep_samples + max_lat
    if y.ndim != 1 or y.size < need:
        raise ParameterError(f"a recording of this plan needs at least {need} samples (mono), got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ParameterError("the recording holds NaN or infinite samples")
    sweep = plan.level * plan.sweep()
    seg = plan.period  # the next sweep's response starts after its latency, beyond the segment
    win_n = int(round(ir_window_s * fs))
    pre = int(round(IR_PRE_S * fs))
    window = _window(win_n + pre, pre)
    irs = []
    for start in plan.starts():
        irs.append(deconvolve(y[start : start + seg], sweep, fs, plan.f1, plan.f2))
    first = irs[0]
    latency = ir_peak(first, search=slice(0, max_lat + 1))
    lag = int(round(latency))
    rows = []
    for ir in irs:
        taken = np.roll(ir, pre - lag)[: win_n + pre] * window
        rows.append(spectrum_db(taken, fs, f))
    sweeps_db = np.stack(rows)
    response_db = combine_sweeps_db(sweeps_db)
    # The lead silence, shifted as a sweep's recording would be, through the same path.
    quiet = y[: min(plan.lead, seg)]
    noise_ir = deconvolve(quiet, sweep, fs, plan.f1, plan.f2)
    noise_taken = np.roll(noise_ir, pre - lag)[: win_n + pre] * window
    # A lead shorter than the sweep holds less noise energy than a sweep's recording does.
    scale_db = 10.0 * math.log10(max(seg / max(quiet.size, 1), 1.0))
    noise_db = spectrum_db(noise_taken, fs, f) + scale_db
    snr_db = response_db - noise_db
    good = snr_db >= min_snr_db
    repeat = float(np.max(majority_spread_db(sweeps_db)[good])) if np.any(good) else math.inf
    first_sweep = y[plan.lead + lag : plan.lead + lag + plan.sweep_samples]
    return Measurement(
        freqs=f,
        response_db=response_db,
        sweeps_db=sweeps_db,
        noise_db=noise_db,
        snr_db=snr_db,
        band_db=band_response_db(f, response_db),
        latency=latency,
        peak=float(np.max(np.abs(y))) if y.size else 0.0,
        noise_rms_db=_rms_db(y[: plan.lead]),
        signal_rms_db=_rms_db(first_sweep),
        clipped=clipped_samples(y),
        repeatability_db=repeat,
        loss=response_loss(y, plan, latency),
    )
