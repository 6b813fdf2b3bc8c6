"""Offline following: a whole signal through the same :class:`Tracker`, latency compensated.

The signal (mono, or several channels mixed to their mean, or each channel on its own) is fed
block by block to a tracker. Before it, the tracker is primed: in vibration mode with the
time-reversed first two seconds crossfaded into the signal (a scan is a stationary process cut
anywhere: the filters and the 30-band windows start settled; see :func:`primer`), in audio mode with silence (a file
starts from nothing: a sound at t = 0 is an onset). After it, the same padding on the other side
lets the last ``latency`` samples reach a frame. Frame times are the frames' ends minus the
tracker's latency, so a step at time t shows at time t.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.follow.frames import TrackFrames
from vibsynth.dsp.follow.params import Focus, Mode, TrackerParams, default_params
from vibsynth.dsp.follow.tracker import BALANCE_LIMITS, Tracker, count_clipped
from vibsynth.dsp.follow.vibration import VibrationAnalyzer
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB
from vibsynth.errors import ParameterError

if TYPE_CHECKING:
    from typing_extensions import Unpack  # typing.Unpack from Python 3.11

__all__ = [
    "FollowOptions",
    "FollowResult",
    "follow",
    "follow_channels",
    "window_analysis",
    "primer",
    "mirror_after",
    "MAX_CHANNELS",
    "PRIME_S",
    "SPLICE_S",
    "OFFLINE_BLOCK",
]

#: Input channels accepted by :func:`follow`.
MAX_CHANNELS = 64
#: Seconds of priming before the signal (and padding after it).
PRIME_S = 2.0
#: Samples fed per call (the output does not depend on it).
OFFLINE_BLOCK = 65536


@dataclass(frozen=True)
class FollowResult:
    """Knob trajectories of a signal, aligned to it.

    Attributes
    ----------
    times : ndarray, shape (n_frames,)
        Seconds into the input that each frame reflects (frame end minus the latency).
    intensity, balance, level_db, onset_strength : ndarray, shape (n_frames,)
        As :class:`~vibsynth.dsp.follow.frames.TrackFrames`.
    gate_open : ndarray of bool, shape (n_frames,)
    output_level_db : ndarray, shape (n_frames,)
        The 80-200 Hz band level the engine plays for each intensity (``-inf`` at 0).
    fs : float
        Input rate.
    hop_s, latency_s : float
    mode, focus : str
    duration_s : float
    silent : bool
        The gate never opened: the output is silence.
    nonfinite_samples, clipped_samples, clamped_frames : int
        Counted bad input (NaN/inf replaced by 0; flat-topped runs) and frames whose level lay
        outside the knob range.
    notes : list of str
        One sentence per thing worth saying (silence, clipping, NaN, clamping).
    """

    times: NDArray[np.float64]
    intensity: NDArray[np.float64]
    balance: NDArray[np.float64]
    level_db: NDArray[np.float64]
    onset_strength: NDArray[np.float64]
    gate_open: NDArray[np.bool_]
    output_level_db: NDArray[np.float64]
    fs: float
    hop_s: float
    latency_s: float
    mode: str
    focus: str
    duration_s: float
    silent: bool
    nonfinite_samples: int = 0
    clipped_samples: int = 0
    clamped_frames: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def onsets(self) -> list[tuple[float, float]]:
        """``(time_s, strength)`` of every transient."""
        idx = np.flatnonzero(self.onset_strength > 0)
        return [(float(self.times[i]), float(self.onset_strength[i])) for i in idx]

    def __len__(self) -> int:
        return int(self.times.size)


def _as_channels(x: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, np.newaxis]
    if arr.ndim != 2 or arr.shape[1] < 1 or arr.shape[1] > MAX_CHANNELS:
        raise ParameterError(
            f"follow takes a signal of shape (n,) or (n, channels) with 1..{MAX_CHANNELS} channels, got {arr.shape}"
        )
    return arr


#: Seconds over which the primer fades into the signal (equal power): smooth enough that the
#: crossfade smears the spectrum by only ~30 Hz, short enough to touch only the first 30 ms.
SPLICE_S = 0.03


def primer(x: NDArray[np.float64], length: int, splice: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A stationary lead-in for ``x``, spliced into it by an equal-power crossfade.

    A hard join (a reflection's slope kink, an offset's step) puts broadband energy into the
    narrow low bands, which ring with it for a second and lower a bright signal's balance; a
    smooth crossfade of two segments of the same process only smears the spectrum by
    ``1 / splice``. The lead-in is ``x`` itself, time-reversed, taken from ``2 splice`` on so the
    two sides of the crossfade are not correlated; the mean of ``x``'s first second is held
    aside while crossfading (an offset is not a noise).

    Returns
    -------
    lead : ndarray
        Samples to feed before ``x`` (empty for a signal too short to lend them).
    head : ndarray
        ``x``'s first ``splice`` samples as spliced (fed in their place).
    """
    k = int(splice)
    m = min(int(length), x.size - 3 * k)
    if k < 1 or m <= 0:
        return np.zeros(0), x[:0]
    mu = float(x[: max(length, 1)].mean())
    source = x[2 * k : 2 * k + m + k][::-1] - mu  # lead (m) then the crossfade's fading side (k)
    theta = 0.5 * np.pi * (np.arange(k) + 0.5) / k
    head = mu + (x[:k] - mu) * np.sin(theta) + source[m:] * np.cos(theta)
    return np.asarray(source[:m] + mu, dtype=np.float64), np.asarray(head, dtype=np.float64)


def mirror_after(x: NDArray[np.float64], length: int) -> NDArray[np.float64]:
    """``length`` samples after ``x``: its end reflected (zeros beyond its length)."""
    tail = x[-2 : -length - 2 : -1] if x.size > 1 else x[:0]
    return np.concatenate((tail, np.zeros(max(0, length - tail.size))))


def _run(
    x: NDArray[np.float64],
    fs: float,
    params: TrackerParams,
    basis: Basis,
    ceiling_db: float,
    range_db: float,
    balance_limits: tuple[float, float],
    uniform: bool = False,
) -> tuple[TrackFrames, Tracker]:
    tracker = Tracker(
        fs=fs,
        params=params,
        basis=basis,
        ceiling_db=ceiling_db,
        range_db=range_db,
        balance_limits=balance_limits,
        uniform_windows=uniform,
    )
    n = x.size
    tail_len = tracker.latency + tracker.hop
    if params.mode == "vibration":
        before, head = primer(x, int(round(PRIME_S * fs)), int(round(SPLICE_S * fs)))
        after = mirror_after(x, tail_len)
    else:
        dc = float(x[: int(fs)].mean()) if n else 0.0  # silence at the signal's offset: DC makes no step
        before, head = np.full(int(round(PRIME_S * fs)), dc), x[:0]
        after = np.full(tail_len, float(x[-int(fs) :].mean()) if n else 0.0)
    total_pad = before.size
    tracker.process(before)
    tracker.nonfinite_samples = tracker.clipped_samples = tracker.clamped_frames = 0
    parts = []
    for start in range(0, n, OFFLINE_BLOCK):
        block = x[start : start + OFFLINE_BLOCK]
        if start == 0 and head.size:
            block = np.concatenate((head, block[head.size :]))
        parts.append(tracker.process(block))
    parts.append(tracker.process(after))
    frames = TrackFrames.concat(parts)
    t_end = frames.end_sample - total_pad - tracker.latency
    keep = (t_end > 0) & (t_end <= n)
    # Onsets are seen sooner than the level (within a hop of the rise, against the level's window
    # and filter): each moves to the frame whose compensated time is about half a hop before its
    # detection, and one before the first kept frame belongs to that frame.
    shift = max(0, int(round((tracker.latency - 0.5 * tracker.hop) / tracker.hop)))
    onset = np.zeros_like(frames.onset_strength)
    if shift < onset.size:  # only onsets detected in the signal, not in the primer
        in_signal = frames.end_sample > total_pad
        onset[shift:] = np.where(in_signal, frames.onset_strength, 0.0)[: onset.size - shift]
    early = (t_end <= 0) & (onset > 0)
    if early.any() and keep.any():
        first = int(np.argmax(keep))
        onset[first] = max(onset[first], float(onset[early].max()))
    return (
        TrackFrames(
            end_sample=t_end[keep],
            level_db=frames.level_db[keep],
            intensity=frames.intensity[keep],
            balance=frames.balance[keep],
            gate_open=frames.gate_open[keep],
            onset_strength=onset[keep],
        ),
        tracker,
    )


def _result(frames: TrackFrames, tracker: Tracker, n: int) -> FollowResult:
    p = tracker.params
    fs = tracker.fs
    intensity = frames.intensity
    with np.errstate(divide="ignore"):
        out_level = np.where(intensity > 0, tracker.ceiling_db - tracker.range_db * (1.0 - intensity), -np.inf)
    silent = not bool(frames.gate_open.any())
    clamped = int(np.count_nonzero(frames.gate_open & ((intensity >= 1.0) | (intensity <= 1.0001e-3))))
    notes = []
    if silent:
        notes.append("input is silent (below the gate everywhere): the output is silence")
    if tracker.nonfinite_samples:
        notes.append(f"{tracker.nonfinite_samples} NaN or infinite samples were replaced by 0")
    if tracker.clipped_samples:
        notes.append(
            f"input clips: {tracker.clipped_samples} samples in flat-topped runs; levels there are underestimated"
        )
    if clamped and p.mode == "vibration":
        notes.append(
            f"{clamped} frames lie outside the knob range ({tracker.ceiling_db - tracker.range_db:g} .. "
            f"{tracker.ceiling_db:g} dB band level at gain {p.gain_db:g} dB): played at its edge"
        )
    return FollowResult(
        times=frames.end_sample / fs,
        intensity=intensity,
        balance=frames.balance,
        level_db=frames.level_db,
        onset_strength=frames.onset_strength,
        gate_open=frames.gate_open,
        output_level_db=out_level,
        fs=fs,
        hop_s=tracker.hop / fs,
        latency_s=tracker.latency / fs,
        mode=p.mode,
        focus=p.focus,
        duration_s=n / fs,
        silent=silent,
        nonfinite_samples=tracker.nonfinite_samples,
        clipped_samples=tracker.clipped_samples,
        clamped_frames=clamped,
        notes=notes,
    )


class FollowOptions(TypedDict, total=False):
    """The keyword options of :func:`follow`, :func:`follow_channels` and :func:`vibsynth.follow` (one declaration).

    Attributes
    ----------
    mode : {"vibration", "audio"}
        Default ``vibration``.
    focus : {"all", "effects", "bass", "beat"}
        Audio mode only; default ``all``.
    params : TrackerParams or None
        Overrides ``mode`` and ``focus`` (default: :func:`default_params` of them).
    basis : Basis or None
        Required here in ``dsp``; :func:`vibsynth.follow` loads the packaged one.
    ceiling_db, range_db : float
        The engine's intensity mapping (default -40 and 40 dB).
    balance_limits : tuple of float
        The live balance range (default -3.5, 3.5).
    """

    mode: Mode
    focus: Focus
    params: TrackerParams | None
    basis: Basis | None
    ceiling_db: float
    range_db: float
    balance_limits: tuple[float, float]


def follow(x: ArrayLike, fs: float, **options: Unpack[FollowOptions]) -> FollowResult:
    """Knob trajectories of a whole signal (offline, latency compensated).

    Parameters
    ----------
    x : array_like, shape (n,) or (n, channels)
        Samples; several channels are mixed to their mean (:func:`follow_channels` follows each).
    fs : float
        Sample rate (Hz); the tracker decimates to its internal rate.
    **options
        :class:`FollowOptions`: ``mode``, ``focus``, ``params``, ``basis``, ``ceiling_db``,
        ``range_db``, ``balance_limits``.

    Returns
    -------
    result : FollowResult

    Raises
    ------
    ParameterError
        No basis, a bad shape or rate, an unknown mode or focus, or input shorter than one frame.
    TypeError
        An option that is not one of :class:`FollowOptions`.
    """
    return _follow(x, fs, options, each_channel=False)[0]


def follow_channels(x: ArrayLike, fs: float, **options: Unpack[FollowOptions]) -> list[FollowResult]:
    """:func:`follow` each input channel on its own (stereo -> two actuators); the same options.

    Returns
    -------
    results : list of FollowResult
        One per column of ``x``.
    """
    return _follow(x, fs, options, each_channel=True)


def _follow(x: ArrayLike, fs: float, options: FollowOptions, *, each_channel: bool) -> list[FollowResult]:
    unknown = sorted(set(options) - set(FollowOptions.__annotations__))
    if unknown:
        raise TypeError(f"follow() got an unexpected keyword argument {unknown[0]!r}")
    basis = options.get("basis")
    if basis is None:
        raise ParameterError("follow needs a basis (vibsynth.follow loads the packaged one)")
    params = options.get("params")
    p = params if params is not None else default_params(options.get("mode", "vibration"), options.get("focus", "all"))
    ceiling_db = options.get("ceiling_db", DEFAULT_CEILING_DB)
    range_db = options.get("range_db", DEFAULT_RANGE_DB)
    balance_limits = options.get("balance_limits", BALANCE_LIMITS)
    arr = _as_channels(x)
    probe = Tracker(
        fs=fs, params=p, basis=basis, ceiling_db=ceiling_db, range_db=range_db, balance_limits=balance_limits
    )
    if arr.shape[0] < probe.hop:
        raise ParameterError(
            f"input is {arr.shape[0]} sample(s) long: following needs at least one frame "
            f"({probe.hop} samples, {1000 * probe.hop / fs:.1f} ms at {fs:g} Hz)"
        )
    bad = ~np.isfinite(arr)
    nonfinite = np.count_nonzero(bad, axis=0)
    if bad.any():
        arr = np.where(bad, 0.0, arr)
    clipped = [count_clipped(arr[:, c]) for c in range(arr.shape[1])]
    if each_channel:
        columns = [(arr[:, c], int(nonfinite[c]), clipped[c]) for c in range(arr.shape[1])]
    else:
        columns = [(arr.mean(axis=1), int(nonfinite.sum()), sum(clipped))]
    results = []
    for col, n_bad, n_clipped in columns:
        frames, tracker = _run(col, float(fs), p, basis, ceiling_db, range_db, balance_limits)
        tracker.nonfinite_samples, tracker.clipped_samples = n_bad, n_clipped
        results.append(_result(frames, tracker, col.size))
    return results


def window_analysis(
    x: ArrayLike, *, fs: float, basis: Basis, window_s: float, hop_s: float
) -> tuple[int, int, NDArray[np.float64], NDArray[np.float64]]:
    """The tracker's vibration analysis at the codec's windows: band powers and levels per window.

    A :class:`Tracker` in vibration mode with ``level_ms = balance_ms = window`` and
    ``uniform_windows`` (every band over the window, the bank run every hop, no bias
    correction: the codec pools windows into segments itself), primed like :func:`follow`, so
    that frame ``i`` covers ``[i hop, i hop + window)`` of the input once the level filter's
    delay is compensated; each band's own filter delay is compensated too (offline only).

    Parameters
    ----------
    x : array_like, shape (n,)
    fs : float
    basis : Basis
    window_s, hop_s : float

    Returns
    -------
    window, hop : int
        In input samples (whole multiples of the decimation factor).
    band_power : ndarray, shape (n_frames, n_bands)
        ``n_frames = (n - window) // hop + 1``.
    level_db : ndarray, shape (n_frames,)
        80-200 Hz band level of each window (``-inf`` when silent).
    """
    arr = np.asarray(x, dtype=np.float64)
    params = TrackerParams(level_ms=1e3 * window_s, balance_ms=1e3 * window_s, hop_ms=1e3 * hop_s, transients=False)
    tracker = Tracker(fs=fs, params=params, basis=basis, uniform_windows=True)
    hop = tracker.hop
    an = tracker.analyzer
    assert isinstance(an, VibrationAnalyzer)
    window = tracker.level_window
    n_frames = (arr.size - window) // hop + 1 if arr.size >= window else 0
    if n_frames <= 0:
        return window, hop, np.zeros((0, basis.n_bands)), np.zeros(0)
    delay = int(round(tracker.filter_delay_s * fs))
    # Offline the bands can wait for each other: each band's frames are shifted by its filter's
    # delay beyond the level filter's, so a level step is one step in every band at once (a
    # causal bank's low bands lag it by up to 0.2 s, which would read as a change of t1).
    shift = np.round((an.band_delay_s - an.filter_delay_s) * an.fs / an.hop).astype(np.intp)
    extra = int(max(0, shift.max())) * hop
    lead, head = primer(arr, int(round(PRIME_S * fs)), int(round(SPLICE_S * fs)))
    align = (-(lead.size + window + delay)) % hop  # frame ends land on i hop + window + delay
    before = np.concatenate((np.zeros(align), lead))
    arr = np.concatenate((head, arr[head.size :]))
    after = mirror_after(arr, delay + hop + extra)
    tracker.process(before)
    ends, levels, powers = [], [], []
    for block in [arr[start : start + OFFLINE_BLOCK] for start in range(0, arr.size, OFFLINE_BLOCK)] + [after]:
        f = tracker.process(block)
        ends.append(f.end_sample)
        levels.append(f.level_db)
        powers.append(tracker.last_band_power)
    first = int(np.searchsorted(np.concatenate(ends), before.size + window + delay))
    level = np.concatenate(levels)[first : first + n_frames]
    every = np.concatenate(powers)[first:]
    rows = np.clip(np.arange(n_frames)[:, np.newaxis] + shift[np.newaxis, :], 0, every.shape[0] - 1)
    power = np.take_along_axis(every, rows, axis=0)
    return window, hop, power, level
