"""Follow offline: a sound file through the tracker, streamed, into a clip or a rendered haptic track.

One pipeline for every offline use of the tracker (``vibsynth clip from-audio``, ``vibsynth
render --follow``, a folder of either)::

    sound file blocks (any channels, any rate)  ->  Tracker.process (channels mixed to their mean,
    decimated inside)  ->  frames aligned to the input  ->  a clip (simplified)  |  engine cues

* **The same tracker as live**, with the mode's documented defaults framed every
  :data:`OFFLINE_HOP_MS` (:func:`offline_params`), primed and flushed as
  :func:`vibsynth.dsp.follow.offline.follow` does: a file gives the frames ``follow`` gives its
  samples with the same parameters.
* **Streaming**: the file is read :data:`READ_BLOCK_S` at a time; nothing grows with its
  length but a clip's frames (a clip holds at most 10 minutes). A render keeps one block of
  input, one of output and the engine: flat memory on an hour of audio.
* **Alignment**: the tracker is causal, so a frame reflects its input ``Tracker.latency``
  samples late; every frame is moved back by that much (``at = end_sample - latency``), and
  the input's last ``latency`` samples are flushed through with silence. An impulse at ``t``
  in the input is a transient at ``t`` in the clip and in the render.
* **Transients**: a frame with an onset (strength ``s`` in (0, 1]) lifts the intensity to
  :func:`~vibsynth.dsp.follow.onsets.transient_peak` ``= intensity + s * TRANSIENT_BOOST`` (at
  most 1, the live follower's lift too), which decays
  linearly in knob units (exponentially in amplitude) back to the curve over
  ``clips.transient_decay_ms``: a clip transient, played the same way by the clip player and by
  ``render --follow``.
* **Simplification** (clips): intensity and balance are simplified jointly by
  :func:`~vibsynth.dsp.simplify.simplify` to at most ``max_keyframes`` keyframes within
  ``tolerance_db`` (intensity, in dB of band level at the engine's ``knobs.range_db``) and
  ``tolerance_balance`` (knob units); the error reached is stated in the result, the clip's
  description and the file's header.
* **Bad input**: one :class:`~vibsynth.errors.InputError` line each (see
  :func:`~vibsynth.formats.sound_reader.open_sound`; also a file shorter than
  :data:`MIN_SECONDS`, and a clip longer than a clip holds). Silence is not an error: the
  result says so (``silent``) and plays silence.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.app.render import Cue
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.follow.offline import PRIME_S, SPLICE_S, mirror_after, primer
from vibsynth.dsp.follow.onsets import transient_peak
from vibsynth.dsp.follow.params import TrackerParams, default_params
from vibsynth.dsp.follow.tracker import Tracker
from vibsynth.dsp.simplify import simplify
from vibsynth.engine.commands import SetKnob
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.sound_reader import open_sound
from vibsynth.settings.clips import Clip, Keyframe, Transient, clip_from_data
from vibsynth.settings.models_clip import MAX_DURATION_MS, MAX_KEYFRAMES, MAX_TRANSIENTS
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.validation import FixedLocator

__all__ = [
    "READ_BLOCK_S",
    "MIN_SECONDS",
    "OFFLINE_HOP_MS",
    "offline_params",
    "DEFAULT_TOLERANCE_DB",
    "DEFAULT_TOLERANCE_BALANCE",
    "AlignedFrames",
    "FollowStream",
    "ClipFromAudio",
    "clip_from_audio",
    "FollowRender",
    "prepare_follow_render",
]

#: Seconds of input read and tracked at a time.
READ_BLOCK_S = 0.25
#: Shortest input followed (a 1-sample file has nothing to follow).
MIN_SECONDS = 0.01
#: Frame period offline (ms): twice the live default's, still well inside the level's ~20 ms
#: resolution; it makes the tracker about 1.3 (vibration) to 1.6 (audio) times faster.
OFFLINE_HOP_MS = 5.0
#: Default largest intensity error of a simplified clip (dB of band level).
DEFAULT_TOLERANCE_DB = 1.0
#: Default largest balance error of a simplified clip (knob units).
DEFAULT_TOLERANCE_BALANCE = 0.1

Progress = Callable[[int, int], None]


def offline_params(mode: str = "vibration", focus: str = "all") -> TrackerParams:
    """The tracker's documented defaults for a mode and focus, framed every :data:`OFFLINE_HOP_MS`."""
    return default_params(mode, focus).with_(hop_ms=OFFLINE_HOP_MS)  # type: ignore[arg-type]


@dataclass(frozen=True)
class AlignedFrames:
    """Tracker frames and onsets moved back to the input sample they reflect.

    Attributes
    ----------
    at : ndarray, int64, shape (n,)
        Input sample index each frame stands for (its end minus the priming and the tracker's
        latency), in (0, frames].
    intensity, balance, level_db : ndarray, float64, shape (n,)
    gate_open : ndarray, bool, shape (n,)
    onset_at : ndarray, int64, shape (m,)
        Input sample index of each onset (its frame's end minus the onset path's own latency).
    onset_strength : ndarray, float64, shape (m,)
        Strength in (0, 1] of each onset.
    """

    at: NDArray[np.int64]
    intensity: NDArray[np.float64]
    balance: NDArray[np.float64]
    level_db: NDArray[np.float64]
    gate_open: NDArray[np.bool_]
    onset_at: NDArray[np.int64]
    onset_strength: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.at.size)

    @classmethod
    def concat(cls, parts: list[AlignedFrames]) -> AlignedFrames:
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) for name in cls.__dataclass_fields__))


def _tracker(fs: float, params: TrackerParams, settings: VibsynthConfig, basis: Basis | None) -> Tracker:
    if basis is None:
        from vibsynth.formats.basis_file import default_basis

        basis = default_basis()
    knobs = settings.knobs
    return Tracker(
        fs=fs,
        params=params,
        basis=basis,
        ceiling_db=knobs.ceiling_db,
        range_db=knobs.range_db,
        balance_limits=(knobs.balance_min, knobs.balance_max),
    )


def onset_latency(tracker: Tracker) -> int:
    """Samples from an onset in the input to the end of the frame that reports it.

    The onset path reacts within a hop (a 5 ms rise), far sooner than the level path's
    :attr:`Tracker.latency` (its window); shifting onsets by the level's latency would put them
    several milliseconds early. Measured on a twin of ``tracker`` (same rate and parameters): an
    impulse in the middle of a hop after half a second of faint noise. ``tracker.latency`` when
    no onset is reported (transients off).
    """
    twin = Tracker(
        fs=tracker.fs,
        params=tracker.params,
        basis=tracker.basis,
        ceiling_db=tracker.ceiling_db,
        range_db=tracker.range_db,
        balance_limits=tracker.balance_limits,
    )
    at = int(round(0.5 * tracker.fs)) // twin.hop * twin.hop + twin.hop // 2
    x = np.random.default_rng(0).standard_normal(at + int(0.3 * tracker.fs)) * 1e-4
    x[at] += 0.5
    frames = twin.process(x)
    hits = np.flatnonzero((frames.onset_strength > 0) & (frames.end_sample > at))
    return int(frames.end_sample[hits[0]] - at) if hits.size else int(tracker.latency)


class FollowStream:
    """A sound file through the tracker, frames aligned to the input, block by block.

    The tracker is primed and flushed as :func:`vibsynth.dsp.follow.offline.follow` does it
    (vibration mode: a stationary lead-in made of the file's own start, spliced in, and the
    end mirrored; audio mode: silence on both sides), so a file gives the frames ``follow``
    gives its samples, read :data:`READ_BLOCK_S` at a time.

    Parameters
    ----------
    path : path-like
        A sound file: WAV (PCM or float), FLAC, Ogg Vorbis/Opus, MP3, AIFF... (any channels, mixed
        to their mean; 1 kHz to 768 kHz).
    settings : VibsynthConfig
        The engine's knob mapping (``knobs.ceiling_db``, ``range_db``, balance range).
    params : TrackerParams, optional
        Default: :func:`offline_params` of ``mode`` and ``focus``.
    mode, focus : str
        Used when ``params`` is not given.
    basis : Basis, optional

    Attributes
    ----------
    fs : float
        The input's rate.
    frames : int
        Input frames.
    channels : int
    tracker : Tracker
    onset_latency : int
        See :func:`onset_latency`.
    silent : bool
        After :meth:`blocks` is exhausted: the gate never opened (silence, or below the gate).

    Raises
    ------
    InputError
        An unreadable or unusable file (one line); shorter than :data:`MIN_SECONDS`.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        settings: VibsynthConfig,
        params: TrackerParams | None = None,
        mode: str = "vibration",
        focus: str = "all",
        basis: Basis | None = None,
    ) -> None:
        self.path = Path(path)
        self.params = params if params is not None else offline_params(mode, focus)
        self.reader = open_sound(self.path)
        try:
            self.fs, self.frames, self.channels = self.reader.fs, self.reader.frames, self.reader.channels
            if self.frames < MIN_SECONDS * self.fs:
                n = self.frames
                raise InputError(
                    f"{self.path}: {n} sample{'s' if n != 1 else ''} ({n / self.fs * 1000:.2g} ms) is too short to "
                    f"follow (at least {MIN_SECONDS * 1000:g} ms)"
                )
            try:
                self.tracker = _tracker(self.fs, self.params, settings, basis)
            except ParameterError as exc:
                raise InputError(f"{self.path}: {exc}") from None
            self.onset_latency = onset_latency(self.tracker)
        except BaseException:
            self.reader.close()
            raise
        self.silent = True
        self._offset = 0

    @property
    def seconds(self) -> float:
        return self.frames / self.fs

    def close(self) -> None:
        self.reader.close()

    def __enter__(self) -> FollowStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _aligned(self, x: NDArray[np.float64]) -> AlignedFrames:
        frames = self.tracker.process(x)
        end = np.asarray(frames.end_sample, dtype=np.int64) - self._offset
        at = end - self.tracker.latency
        keep = (at > 0) & (at <= self.frames)
        if np.any(frames.gate_open[keep]):
            self.silent = False
        hits = np.flatnonzero(np.asarray(frames.onset_strength) > 0)
        onset_at = np.clip(end[hits] - self.onset_latency, 0, self.frames)
        inside = end[hits] > 0  # an onset in the priming is none of the file's
        return AlignedFrames(
            at[keep],
            np.asarray(frames.intensity)[keep],
            np.asarray(frames.balance)[keep],
            np.asarray(frames.level_db)[keep],
            np.asarray(frames.gate_open)[keep],
            onset_at[inside],
            np.asarray(frames.onset_strength)[hits][inside],
        )

    def blocks(self, progress: Progress | None = None) -> Iterator[AlignedFrames]:
        """Track the whole file; yield the aligned frames of each block read.

        Parameters
        ----------
        progress : callable, optional
            ``progress(input_frames_done, input_frames_total)`` after each block.
        """
        fs, tracker = self.fs, self.tracker
        prime, splice = int(round(PRIME_S * fs)), int(round(SPLICE_S * fs))
        tail_len = tracker.latency + tracker.hop
        first = self.reader.read(prime + 3 * splice).mean(axis=1)
        if self.params.mode == "vibration":
            before, head = primer(first, prime, splice)
        else:
            before, head = np.zeros(prime), first[:0]
        self._offset = before.size
        tracker.process(before)
        tail = first[-(tail_len + 2) :]
        yield self._aligned(np.concatenate((head, first[head.size :])))
        block = max(1, int(round(READ_BLOCK_S * fs)))
        for x in self.reader.blocks(block):
            mono = x.mean(axis=1)
            tail = np.concatenate((tail, mono))[-(tail_len + 2) :]
            yield self._aligned(mono)
            if progress is not None:
                progress(self.reader.position, self.frames)
        after = mirror_after(tail, tail_len) if self.params.mode == "vibration" else np.zeros(tail_len)
        yield self._aligned(after)


# --------------------------------------------------------------------------- clip
@dataclass(frozen=True)
class ClipFromAudio:
    """A clip made from a sound file, and how close it is.

    Attributes
    ----------
    clip : Clip
    seconds : float
        Input length.
    tracked_frames : int
        Frames the tracker gave (before simplification).
    max_error_db : float
        Largest intensity error of the keyframes' curve against the tracked one (dB of band
        level at ``knobs.range_db``; the knob error x range).
    max_error_balance : float
        Largest balance error (knob units).
    within : bool
        Both errors are within the asked tolerances (False: the keyframe budget ran out first).
    dropped_transients : int
        Onsets left out (weakest first) beyond what a clip holds.
    silent : bool
        The gate never opened: the clip is silence.
    """

    clip: Clip
    seconds: float
    tracked_frames: int
    max_error_db: float
    max_error_balance: float
    within: bool
    dropped_transients: int
    silent: bool

    def summary(self) -> str:
        """One line: what was made and the error reached."""
        c = self.clip
        line = (
            f"{self.seconds:.2f} s -> {len(c.keyframes)} keyframes, {len(c.transients)} transients "
            f"(from {self.tracked_frames:,} frames); max error {self.max_error_db:.2f} dB intensity, "
            f"{self.max_error_balance:.3f} balance"
        )
        if not self.within:
            line += " (the keyframe budget ran out before the tolerances were met)"
        if self.dropped_transients:
            line += f"; {self.dropped_transients} weakest onsets left out (a clip holds {MAX_TRANSIENTS})"
        return line


def _transients(f: AlignedFrames, fs: float, decay_ms: float) -> tuple[list[Transient], int]:
    """The onsets as clip transients at their own times (the strongest :data:`MAX_TRANSIENTS`)."""
    keep = np.arange(f.onset_at.size)
    dropped = max(0, keep.size - MAX_TRANSIENTS)
    if dropped:
        keep = np.sort(np.argsort(-f.onset_strength, kind="stable")[:MAX_TRANSIENTS])
    at = f.onset_at[keep].astype(np.float64)
    curve = np.interp(at, f.at, f.intensity)
    balance = np.interp(at, f.at, f.balance)
    peaks = transient_peak(curve, f.onset_strength[keep])
    out = [
        Transient(t / fs * 1000.0, float(p), float(b), decay_ms)
        for t, p, b in zip(at.tolist(), peaks.tolist(), balance.tolist())
    ]
    return out, dropped


def clip_from_audio(
    stream: FollowStream,
    *,
    name: str,
    settings: VibsynthConfig,
    tolerance_db: float = DEFAULT_TOLERANCE_DB,
    tolerance_balance: float = DEFAULT_TOLERANCE_BALANCE,
    max_keyframes: int = MAX_KEYFRAMES,
    progress: Progress | None = None,
) -> ClipFromAudio:
    """Track a sound file and make a clip of it (see the module notes).

    Parameters
    ----------
    stream : FollowStream
        A file at most 10 minutes long (a clip's longest), not read yet; closed on return.
    name : str
        The clip's name.
    settings : VibsynthConfig
        Knob mapping (``knobs``) and transient decay (``clips.transient_decay_ms``).
    tolerance_db, tolerance_balance : float
        Largest error allowed while simplifying (> 0).
    max_keyframes : int
        At most this many keyframes (2..MAX_KEYFRAMES).
    progress : callable, optional
        ``progress(input_frames_done, input_frames_total)``.

    Returns
    -------
    result : ClipFromAudio

    Raises
    ------
    InputError
        The file (one line), or longer than a clip holds.
    ParameterError
        A tolerance or budget out of range.
    """
    if not (tolerance_db > 0 and tolerance_balance > 0 and math.isfinite(tolerance_db + tolerance_balance)):
        raise ParameterError(f"tolerances must be positive, got {tolerance_db!r} dB and {tolerance_balance!r}")
    if not 2 <= max_keyframes <= MAX_KEYFRAMES:
        raise ParameterError(f"max keyframes must be in 2..{MAX_KEYFRAMES}, got {max_keyframes}")
    with stream:
        if stream.seconds * 1000.0 > MAX_DURATION_MS:
            raise InputError(
                f"{stream.path}: {stream.seconds / 60:.1f} min is longer than a clip holds "
                f"({MAX_DURATION_MS / 60000:g} min); render it with render --follow, or cut it"
            )
        f = AlignedFrames.concat(list(stream.blocks(progress)))
        fs, silent = stream.fs, stream.silent
        seconds = stream.seconds
    if len(f) == 0:  # no frame within the file (shorter than the tracker's first frame): silence
        zero, no = np.zeros(1), np.zeros(0)
        f = AlignedFrames(np.zeros(1, np.int64), zero, zero, zero - np.inf, zero > 0, no.astype(np.int64), no)
    range_db = settings.knobs.range_db
    t_ms = f.at / fs * 1000.0
    values = np.stack([f.intensity, f.balance], axis=1)
    kept = simplify(t_ms, values, [tolerance_db / range_db, tolerance_balance], max_points=max_keyframes)
    keys = tuple(Keyframe(float(t_ms[k]), float(f.intensity[k]), float(f.balance[k])) for k in kept.index)
    transients, dropped = _transients(f, fs, settings.clips.transient_decay_ms)
    duration = max(seconds * 1000.0, keys[-1].t_ms)
    error_db, error_balance = float(kept.max_error[0] * range_db), float(kept.max_error[1])
    p = stream.params
    description = (
        f"Followed from {stream.path.name} ({p.mode} mode"
        + (f", focus {p.focus}" if p.mode == "audio" else "")
        + f"): max error {error_db:.2f} dB intensity, {error_balance:.3f} balance"
        + (" (silent input)" if silent else "")
    )
    clip = Clip(
        name=name,
        duration_ms=duration,
        keyframes=keys,
        transients=tuple(transients),
        tags=("follow",),
        description=description,
    )
    checked = clip_from_data(clip.to_dict(), FixedLocator(f"clip made from {stream.path}"), name)
    return ClipFromAudio(checked, seconds, len(f), error_db, error_balance, kept.within, dropped, silent)


# --------------------------------------------------------------------------- render
@dataclass
class FollowRender:
    """A sound file ready to render as a haptic track through the engine.

    Attributes
    ----------
    engine : Engine
    timeline : iterator of Cue
        Knob moves generated while rendering (the file is tracked as the render pulls them).
    frames : int
        Output frames (the input's length at the engine's rate).
    stream : FollowStream
    """

    engine: Any
    timeline: Iterator[Cue]
    frames: int
    stream: FollowStream

    @property
    def fs(self) -> float:
        return float(self.engine.fs)


def _lifted(
    f: AlignedFrames, pending: deque[tuple[int, float]], state: list[float], decay_s: float, fs: float
) -> NDArray[np.float64]:
    """The block's intensity with onsets overlaid: a peak at the first frame at or after each onset,
    decaying linearly (in knob units) to the curve over ``decay_s``. ``state`` carries
    ``[peak, peak_time]`` across blocks; onsets after the block's last frame stay in ``pending``."""
    curve = f.intensity
    n = curve.size
    times = f.at / fs
    peak = np.full(n, np.nan)
    while pending and pending[0][0] <= f.at[-1]:
        onset, strength = pending.popleft()
        k = int(np.searchsorted(f.at, onset))
        lifted = float(transient_peak(curve[k], np.float64(strength)))
        if lifted > curve[k] and not lifted <= peak[k]:
            peak[k] = lifted
    has = ~np.isnan(peak)
    last = np.maximum.accumulate(np.where(has, np.arange(n), -1))
    carried = last < 0
    peak_v = np.where(carried, state[0], peak[np.maximum(last, 0)])
    peak_t = np.where(carried, state[1], times[np.maximum(last, 0)])
    if has.any():
        state[0], state[1] = float(peak_v[-1]), float(peak_t[-1])
    u = (times - peak_t) / decay_s
    with np.errstate(invalid="ignore"):
        overlay = peak_v + (curve - peak_v) * u
    return np.where(u < 1, np.maximum(curve, overlay), curve)


def _cues(stream: FollowStream, fs_out: float, decay_s: float, progress: Progress | None) -> Iterator[Cue]:
    """Each aligned frame as a glide of one hop ending on its frame; onsets overlaid as decaying peaks.

    An onset is reported before the frames of its time (its path is faster than the level's):
    it waits in ``pending`` until the first frame at or after it, whose intensity it lifts. A
    knob whose value did not change is not sent again.
    """
    ratio = fs_out / stream.fs
    hop_s = stream.tracker.hop / stream.fs
    hop_out = int(round(stream.tracker.hop * ratio))
    previous = {"intensity": math.nan, "balance": math.nan}
    state = [0.0, -math.inf]
    pending: deque[tuple[int, float]] = deque()
    for f in stream.blocks(progress):
        pending.extend(zip(f.onset_at.tolist(), f.onset_strength.tolist()))
        if not len(f):
            continue
        frames = np.maximum(0, np.round(f.at * ratio).astype(np.int64) - hop_out).tolist()
        values = {"intensity": _lifted(f, pending, state, decay_s, stream.fs), "balance": f.balance}
        changed = {}
        for knob, v in values.items():
            before = np.concatenate(([previous[knob]], v[:-1]))
            changed[knob] = (v != before).tolist()
            previous[knob] = float(v[-1])
        ivals, bvals = values["intensity"].tolist(), values["balance"].tolist()
        for k, frame in enumerate(frames):
            if changed["intensity"][k]:
                yield Cue(frame, SetKnob("intensity", ivals[k], at_frame=frame, glide_s=hop_s))
            if changed["balance"][k]:
                yield Cue(frame, SetKnob("balance", bvals[k], at_frame=frame, glide_s=hop_s))


def prepare_follow_render(
    stream: FollowStream,
    *,
    settings: VibsynthConfig,
    basis: Basis | None = None,
    engine: Any = None,
    progress: Progress | None = None,
) -> FollowRender:
    """Open a sound file and the engine that renders its haptic track (see the module notes).

    Parameters
    ----------
    stream : FollowStream
        The file, not read yet (the render reads it; close it afterwards, or use ``with``).
    settings : VibsynthConfig
        The engine (rate, bank, knobs) and the transient decay.
    basis : Basis, optional
        For the engine's bank (default: the shipped basis).
    engine : Engine, optional
        A fresh engine; default :func:`vibsynth.app.service.build_engine`.
    progress : callable, optional
        ``progress(input_frames_done, input_frames_total)`` as the input is tracked (the
        renderer's own progress counts output frames).

    Raises
    ------
    InputError
        The file, as it is read (one line each).
    """
    try:
        if engine is None:
            from vibsynth.app.service import build_engine

            engine = build_engine(settings, basis=basis)
        fs_out = float(engine.fs)
        frames = max(1, int(round(stream.frames * fs_out / stream.fs)))
        decay_s = settings.clips.transient_decay_ms / 1000.0
        timeline = _cues(stream, fs_out, decay_s, progress)
    except BaseException:
        stream.close()
        raise
    return FollowRender(engine, timeline, frames, stream)
