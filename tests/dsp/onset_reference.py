"""A reference onset detector for the follow tests, independent of the code under test.

Spectral flux as in Dixon (2006) and Böck & Widmer (2013): the log magnitude
``log10(1 + 100 |X|)`` of a Hann-windowed STFT (11.6 ms window, 2 ms hop), grouped into
half-octave bands 60 Hz - 16 kHz, its half-wave rectified rise over the largest of the frames
4-12 ms before (a rise above the recent past, not the ripple of a low tone in a short window),
summed over bands. Onsets are the local maxima of that flux over +-30 ms that stand above the
median of the surrounding 200 ms by ``DELTA`` of the flux's scale (its 99th percentile), at
least 30 ms apart, at the frame's centre (within 4 ms of synthetic hits: tested in
tests/dsp/test_follow_onsets.py). *Strong* onsets have a flux of at least ``STRONG_FRACTION``
of the scale and are at most ``STRONG_BELOW_DB`` below the loop's loudest 30 ms.

Also the matching of a follower's transients against the reference onsets
(:func:`match_onsets`) and a synthetic drum pattern (:func:`drum_hits`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal

WINDOW_S = 0.0116
HOP_S = 0.002
FLUX_LAG_S = 0.004
FLUX_SPAN_S = 0.012
PEAK_HALF_S = 0.03
MEDIAN_S = 0.2
DELTA = 0.15
MIN_GAP_S = 0.03
STRONG_FRACTION = 0.4
#: the flux's scale: this percentile of its frames (the loop's largest is often its first hit, out of silence)
SCALE_PERCENTILE = 99.0
#: a strong onset is also at most this far below the loop's loudest LEVEL_S (a faint tick 40 dB
#: under the kicks is an onset of log flux, not a hit to feel)
STRONG_BELOW_DB = 30.0
LEVEL_S = 0.03
#: a transient within this of an onset finds it (the issue's alignment budget)
TOLERANCE_S = 0.010


@dataclass(frozen=True)
class Onsets:
    """Reference onsets of a sound.

    Attributes
    ----------
    times : ndarray, shape (m,)
        Seconds.
    flux : ndarray, shape (m,)
        The flux at each onset.
    strong : ndarray of bool, shape (m,)
        Flux >= STRONG_FRACTION of the largest.
    """

    times: NDArray[np.float64]
    flux: NDArray[np.float64]
    strong: NDArray[np.bool_]


def spectral_flux(x: NDArray[np.float64], fs: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Frame times (s, the window's centre) and the band-summed rectified log-magnitude flux."""
    n = int(round(WINDOW_S * fs))
    hop = max(1, int(round(HOP_S * fs)))
    lag = max(1, int(round(FLUX_LAG_S / HOP_S)))
    padded = np.concatenate((np.zeros(n), np.asarray(x, dtype=np.float64), np.zeros(n)))
    starts = np.arange(0, padded.size - n, hop)
    frames = padded[starts[:, None] + np.arange(n)] * np.hanning(n)
    mag = np.abs(np.fft.rfft(frames, axis=1))
    freqs = np.fft.rfftfreq(n, 1 / fs)
    edges = 60.0 * 2.0 ** (np.arange(0, 20) / 2)
    edges = edges[edges < min(16000.0, 0.5 * fs)]
    bands = np.stack(
        [mag[:, (freqs >= lo) & (freqs < hi)].sum(axis=1) for lo, hi in zip(edges[:-1], edges[1:])], axis=1
    )
    logmag = np.log10(1.0 + 100.0 * bands)
    # the rise over the largest of the frames FLUX_LAG_S..FLUX_SPAN_S before: a rise above the recent
    # past, not the ripple of a low tone in a short window
    span = max(lag, int(round(FLUX_SPAN_S / HOP_S)))
    m = logmag.shape[0]
    flux = np.zeros(m)
    if m > span:
        recent = np.max([logmag[span - d : m - d] for d in range(lag, span + 1)], axis=0)
        flux[span:] = np.maximum(0.0, logmag[span:] - recent).sum(axis=1)
    times = (starts + n / 2) / fs - n / fs
    return times, flux


def reference_onsets(x: NDArray[np.float64], fs: float) -> Onsets:
    """Onsets of ``x`` (mono, any rate) by spectral flux with an adaptive median threshold."""
    times, flux = spectral_flux(x, fs)
    half = int(round(PEAK_HALF_S / HOP_S))
    local_max = flux == ndimage.maximum_filter1d(flux, 2 * half + 1, mode="constant")
    median = ndimage.median_filter(flux, int(round(MEDIAN_S / HOP_S)) | 1, mode="nearest")
    peak = float(np.percentile(flux, SCALE_PERCENTILE)) if flux.size else 0.0
    inside = times < x.size / fs - WINDOW_S  # a loop cut off at its end is no onset
    candidates = np.flatnonzero(local_max & (flux > median + DELTA * peak) & (flux > 0) & inside)
    kept: list[int] = []
    for i in candidates:
        if kept and times[i] - times[kept[-1]] < MIN_GAP_S:
            if flux[i] > flux[kept[-1]]:
                kept[-1] = int(i)
            continue
        kept.append(int(i))
    idx = np.asarray(kept, dtype=np.intp)
    at = times[idx]
    f = flux[idx]
    level = _levels_db(np.asarray(x, dtype=np.float64), fs, at)
    top = float(np.max(_levels_db(np.asarray(x, dtype=np.float64), fs, np.arange(0.0, x.size / fs, LEVEL_S / 2))))
    return Onsets(at, f, (f >= STRONG_FRACTION * peak) & (level >= top - STRONG_BELOW_DB))


def _levels_db(x: NDArray[np.float64], fs: float, at: NDArray[np.float64]) -> NDArray[np.float64]:
    """Level (dB re full scale RMS) of the LEVEL_S after each time."""
    n = int(round(LEVEL_S * fs))
    cum = np.concatenate(([0.0], np.cumsum(x * x)))
    i = np.clip(np.round(np.asarray(at) * fs).astype(np.intp), 0, x.size)
    j = np.minimum(i + n, x.size)
    power = (cum[j] - cum[i]) / np.maximum(1, j - i)
    return np.asarray(10.0 * np.log10(power + 1e-20), dtype=np.float64)


@dataclass(frozen=True)
class Match:
    """How a follower's transients match the reference onsets.

    Attributes
    ----------
    hit_rate : float
        Share of strong onsets with a transient within TOLERANCE_S.
    per_onset : float
        Transients per strong onset.
    doubles : int
        Strong onsets with two or more transients from TOLERANCE_S before to 50 ms after them.
    median_ms : float
        Median of (transient - onset) over the matched strong onsets (ms; NaN if none).
    strong, matched, transients : int
    """

    hit_rate: float
    per_onset: float
    doubles: int
    median_ms: float
    strong: int
    matched: int
    transients: int


def match_onsets(onsets: Onsets, transients_s: NDArray[np.float64]) -> Match:
    """Match transient times (s) against the strong reference onsets."""
    t = np.sort(np.asarray(transients_s, dtype=np.float64))
    strong = onsets.times[onsets.strong]
    errors = []
    doubles = 0
    for o in strong:
        d = t - o
        near = np.abs(d) <= TOLERANCE_S
        if near.any():
            errors.append(float(d[near][np.argmin(np.abs(d[near]))]))
        if np.count_nonzero((d >= -TOLERANCE_S) & (d <= 0.05)) >= 2:
            doubles += 1
    n = max(1, strong.size)
    return Match(
        hit_rate=len(errors) / n,
        per_onset=t.size / n,
        doubles=doubles,
        median_ms=float(np.median(errors) * 1e3) if errors else float("nan"),
        strong=int(strong.size),
        matched=len(errors),
        transients=int(t.size),
    )


def drum_hits(
    fs: float, rng: np.random.Generator, seconds: float = 4.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A synthetic drum pattern: main hits 100-200 ms apart with ghost notes between.

    Main hits alternate kick-like (a 110-50 Hz sine sweep, 150 ms decay, with a beater click of
    noise above 2 kHz) and snare-like (band-passed noise and a 200 Hz tone, 120 ms decay) at
    random levels within 6 dB (accents),
    with closed hi-hat ticks (high-passed noise, 25 ms decay) 20 dB below on most of them; ghost
    notes (quiet snare, 20-26 dB below) land in about half of the gaps, at least 40 ms from a hit.

    Returns
    -------
    x : ndarray, shape (n,)
        The sound, peak 0.5.
    hits : ndarray, shape (h,)
        Times (s) of the main hits.
    ghosts : ndarray, shape (g,)
        Times (s) of the ghost notes.
    """
    n = int(seconds * fs)
    x = np.zeros(n)
    t_hit = np.arange(int(0.3 * fs)) / fs
    hp = signal.butter(4, 6000.0 / (0.5 * fs) if fs > 13000 else 0.9, btype="high", output="sos")
    beater = signal.butter(2, 2000.0 / (0.5 * fs), btype="high", output="sos")
    bp = signal.butter(2, (300.0 / (0.5 * fs), min(0.9, 5000.0 / (0.5 * fs))), btype="band", output="sos")

    def kick() -> NDArray[np.float64]:
        phase = 2 * np.pi * np.cumsum(50.0 + 60.0 * np.exp(-t_hit / 0.03)) / fs
        body = np.sin(phase) * np.exp(-t_hit / 0.15)
        click = signal.sosfilt(beater, rng.standard_normal(t_hit.size)) * np.exp(-t_hit / 0.006)
        return body + click

    def snare() -> NDArray[np.float64]:
        noise = signal.sosfilt(bp, rng.standard_normal(t_hit.size)) * np.exp(-t_hit / 0.12)
        return noise * 1.5 + 0.5 * np.sin(2 * np.pi * 200.0 * t_hit) * np.exp(-t_hit / 0.05)

    def hat() -> NDArray[np.float64]:
        return signal.sosfilt(hp, rng.standard_normal(t_hit.size)) * np.exp(-t_hit / 0.025)

    def add(at: float, sound: NDArray[np.float64], gain: float) -> None:
        i = int(round(at * fs))
        m = min(sound.size, n - i)
        x[i : i + m] += gain * sound[:m]

    hits: list[float] = []
    ghosts: list[float] = []
    at = 0.2
    k = 0
    while at < seconds - 0.3:
        hits.append(at)
        add(at, kick() if k % 2 == 0 else snare(), 10 ** (-rng.uniform(0, 6) / 20))
        if rng.random() < 0.7:
            add(at, hat(), 0.1)
        gap = rng.uniform(0.1, 0.2)
        if gap >= 0.14 and rng.random() < 0.5:
            g = at + rng.uniform(0.04, gap - 0.04)
            ghosts.append(g)
            add(g, snare(), 10 ** (-rng.uniform(20, 26) / 20))
        at += gap
        k += 1
    x *= np.minimum(1.0, (n - np.arange(n)) / (0.05 * fs))  # no cut at the end
    x *= 0.5 / np.max(np.abs(x))
    return x, np.array(hits), np.array(ghosts)
