"""The timeline compiler: a clip (plus gain, rate, loops and a start frame) -> engine knob moves.

A clip is two curves of knob values over time (intensity and balance), set by keyframes,
plus transients on top. The engine already plays *linear* knob ramps sample-exactly (see
:mod:`vibsynth.engine.engine`: a move to ``v`` with glide ``T`` issued at frame ``f``
reaches ``v`` exactly ``round(T * fs)`` samples later, whatever the block size), so a clip
is compiled into a stream of :class:`KnobMove` objects ``(frame, knob, value, glide_s)``
that a control thread schedules ahead of time. The audio callback never evaluates a clip:
its per-block work stays what it is for any knob move.

How each part becomes moves
---------------------------
* **linear** segment (keyframe ``k`` to ``k+1``): exactly one engine glide, issued at
  keyframe ``k``'s frame, lasting until keyframe ``k+1``'s frame. Played through a real
  engine, the knob equals the straight line between the two (frame-rounded) keyframes at
  every sample.
* **hold**: nothing until the next keyframe, where the knob jumps (glide 0) to its value.
* **smooth**: the clip's own curve (:meth:`Clip.value_at`) cut into linear pieces, split
  in halves until the line is within :data:`SMOOTH_TOLERANCE` knob units of the curve at
  the quarter, half and three-quarter points of every piece (pieces are never shorter
  than :data:`SMOOTH_MIN_PIECE_MS`). For the clip model's cosine ease this keeps the error
  below 0.004 knob units everywhere (0.16 dB of intensity at the default 40 dB range), with
  about 16 pieces for a segment spanning one knob unit (the count grows with the square
  root of the span).
* **transient** ``(t, intensity, balance, decay)``: at ``t`` the intensity jumps to
  ``max(curve, transient intensity)`` and the balance to the transient's balance; both
  then glide linearly back to the curve's value at ``t + decay`` over ``decay``. The
  intensity knob is linear in dB (``engine.py``), so this linear glide is an *exponential*
  amplitude decay. A transient that starts during another's decay takes over from the
  current value (its intensity is the larger of the two).
* **gain** multiplies intensity (the result clamped to [0, 1]; a piece crossing 1 is split
  where it crosses, so the clamp stays exact); **rate** stretches time (2 = twice as fast);
  balance is clamped to the live balance range.
* **loops**: with loop points ``(start, end)`` the clip plays ``0..end``, then ``start..end``
  again ``loops - 1`` times, then ``end..duration`` (the tail); without loop points the
  whole clip repeats. ``loops = 0`` repeats until stopped (no tail).
* A glide longer than the controller's ``glide_max_s`` is cut into pieces on the same line.

Frames: a clip time ``u`` ms after the start (loops unrolled) plays at frame
``start_frame + round(u * fs / (1000 * rate))``; every keyframe is rounded on its own, so
there is no drift over long loops.

The compiler is pure (no engine, no threads): both the live player
(:mod:`vibsynth.control.clips.player`) and ``vibsynth render --clip`` use it. The moves are
generated lazily, in frame order, so an endless loop costs only what is pulled.
"""

from __future__ import annotations

import heapq
import math
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

from vibsynth.control.controller import check_range
from vibsynth.engine.commands import KnobName
from vibsynth.errors import ParameterError
from vibsynth.limits import CLIP_GAIN_MAX, CLIP_LOOPS_MAX, CLIP_RATE_MAX, CLIP_RATE_MIN
from vibsynth.settings.clips import Clip, Keyframe

__all__ = [
    "GAIN_MAX",
    "RATE_MIN",
    "RATE_MAX",
    "LOOPS_MAX",
    "MIN_LOOP_MS",
    "SMOOTH_TOLERANCE",
    "SMOOTH_MIN_PIECE_MS",
    "ClipLike",
    "KnobMove",
    "Piece",
    "ClipPosition",
    "ClipTimeline",
    "check_play_args",
    "curve_pieces",
]

#: Playback limits: largest gain, rate range, most loop passes (defined in :mod:`vibsynth.limits`).
GAIN_MAX, RATE_MIN, RATE_MAX, LOOPS_MAX = CLIP_GAIN_MAX, CLIP_RATE_MIN, CLIP_RATE_MAX, CLIP_LOOPS_MAX
#: Largest distance (knob units) between a smooth segment's curve and its linear pieces,
#: checked at each piece's quarter points.
SMOOTH_TOLERANCE = 0.004
#: Shortest linear piece of a smooth segment (ms of clip time).
SMOOTH_MIN_PIECE_MS = 1.0
#: Shortest loop region that may be repeated (ms of clip time).
MIN_LOOP_MS = 1.0
#: Values closer than this are the same knob value (no command is sent for the difference).
_SAME = 1e-9
_KNOBS: tuple[KnobName, KnobName] = ("intensity", "balance")


#: What the compiler reads: a clip of the clip model.
ClipLike = Clip


@dataclass(frozen=True, slots=True)
class KnobMove:
    """One engine knob move: at ``frame``, glide ``knob`` to ``value`` over ``glide_s`` (0 = jump).

    Attributes
    ----------
    frame : int
        Stream frame at which the move starts.
    knob : {"intensity", "balance"}
    value : float
        Target, already scaled by gain and clamped.
    glide_s : float
        Seconds to reach it (an integer number of frames / fs).
    """

    frame: int
    knob: KnobName
    value: float
    glide_s: float


@dataclass(frozen=True, slots=True)
class Piece:
    """A linear piece of one knob's curve: ``v0`` at ``t0`` to ``v1`` at ``t1`` (ms; ``t1 >= t0``)."""

    t0: float
    t1: float
    v0: float
    v1: float

    def at(self, t: float) -> float:
        """Value on the line at ``t`` (``v0`` for a zero-length piece)."""
        span = self.t1 - self.t0
        if span <= 0.0:
            return self.v0
        return self.v0 + (self.v1 - self.v0) * ((t - self.t0) / span)

    def cut(self, t0: float, t1: float) -> Piece:
        """The part between ``t0`` and ``t1`` (inside the piece)."""
        return Piece(t0, t1, self.at(t0), self.at(t1))


@dataclass(frozen=True, slots=True)
class ClipPosition:
    """Where a playing clip is.

    Attributes
    ----------
    clip_ms : float
        Position in the clip's own time (0..duration).
    loop_pass : int
        0 = the first pass; k = the k-th repeat of the loop region; ``-1`` = the tail.
    loops_left : int
        Repeats of the loop region still to come after this pass (-1 = until stopped).
    ended : bool
        The clip has played to its end.
    """

    clip_ms: float
    loop_pass: int
    loops_left: int
    ended: bool


def check_play_args(gain: float, rate: float, loops: float) -> tuple[float, float, int]:
    """Validate playback arguments; return ``(gain, rate, loops)``.

    Raises
    ------
    ParameterError
        NaN or out of range, naming the range: gain [0, :data:`GAIN_MAX`], rate
        [:data:`RATE_MIN`, :data:`RATE_MAX`], loops an integer 0 (until stopped) ..
        :data:`LOOPS_MAX`.
    """
    gain = check_range("gain", gain, 0.0, GAIN_MAX)
    rate = check_range("rate", rate, RATE_MIN, RATE_MAX)
    count = check_range("loops", loops, 0, LOOPS_MAX)
    if count != int(count):
        raise ParameterError(f"loops must be a whole number (0 = until stopped), got {count:g}")
    return gain, rate, int(count)


# --------------------------------------------------------------------------- clip curves
def _smooth_points(clip: ClipLike, a: Keyframe, b: Keyframe) -> list[tuple[float, float, float]]:
    """Breakpoints ``(t, intensity, balance)`` of a smooth segment, ``a`` and ``b`` included."""
    out = [(a.t_ms, a.intensity, a.balance)]
    stack = [(a.t_ms, (a.intensity, a.balance), b.t_ms, (b.intensity, b.balance))]
    while stack:  # depth first, right half pushed first: points come out in time order
        t0, v0, t1, v1 = stack.pop()
        span = t1 - t0
        mid = t0 + span / 2
        vm = clip.value_at(mid)
        if span >= 2 * SMOOTH_MIN_PIECE_MS and not _close_to_line(clip, t0, v0, t1, v1, vm):
            stack.append((mid, vm, t1, v1))
            stack.append((t0, v0, mid, vm))
        else:
            out.append((t1, v1[0], v1[1]))
    return out


def _close_to_line(
    clip: ClipLike, t0: float, v0: tuple[float, float], t1: float, v1: tuple[float, float], vm: tuple[float, float]
) -> bool:
    for frac, value in ((0.5, vm), (0.25, None), (0.75, None)):
        actual = clip.value_at(t0 + frac * (t1 - t0)) if value is None else value
        for k in (0, 1):
            if abs(actual[k] - (v0[k] + (v1[k] - v0[k]) * frac)) > SMOOTH_TOLERANCE:
                return False
    return True


def curve_pieces(clip: ClipLike) -> tuple[tuple[Piece, ...], tuple[Piece, ...]]:
    """The clip's two curves as contiguous linear pieces covering ``[0, duration_ms]``.

    Returns
    -------
    (intensity, balance) : tuple of tuple of Piece
        In clip time (ms), without gain, rate or transients. A jump is where one piece
        ends at another value than the next one starts with.
    """
    keys = sorted(clip.keyframes, key=lambda k: k.t_ms)
    if not keys:
        raise ParameterError(f"clip {clip.name!r} has no keyframes")
    duration = float(clip.duration_ms)
    pieces: tuple[list[Piece], list[Piece]] = ([], [])

    def add(t0: float, t1: float, i0: float, i1: float, b0: float, b1: float) -> None:
        if t1 > t0:
            pieces[0].append(Piece(t0, t1, i0, i1))
            pieces[1].append(Piece(t0, t1, b0, b1))

    first = keys[0]
    i_start, b_start = clip.value_at(0.0)
    add(0.0, min(first.t_ms, duration), i_start, i_start, b_start, b_start)
    for a, b in zip(keys, keys[1:]):
        t1 = min(b.t_ms, duration)
        if a.interp == "hold":
            add(a.t_ms, t1, a.intensity, a.intensity, a.balance, a.balance)
        elif a.interp == "smooth" and b.t_ms > a.t_ms:
            points = _smooth_points(clip, a, b)
            for (s0, i0, b0), (s1, i1, b1) in zip(points, points[1:]):
                if s0 < duration:
                    end = min(s1, duration)
                    frac = 1.0 if s1 == s0 else (end - s0) / (s1 - s0)
                    add(s0, end, i0, i0 + (i1 - i0) * frac, b0, b0 + (b1 - b0) * frac)
        else:
            frac = 1.0 if b.t_ms == a.t_ms else (t1 - a.t_ms) / (b.t_ms - a.t_ms)
            add(
                a.t_ms,
                t1,
                a.intensity,
                a.intensity + (b.intensity - a.intensity) * frac,
                a.balance,
                a.balance + (b.balance - a.balance) * frac,
            )
    last = keys[-1]
    add(last.t_ms, duration, last.intensity, last.intensity, last.balance, last.balance)
    return tuple(pieces[0]), tuple(pieces[1])


_CACHE: dict[int, tuple[ClipLike, tuple[tuple[Piece, ...], tuple[Piece, ...]]]] = {}
_CACHE_SIZE = 64
_CACHE_LOCK = threading.Lock()


def _cached_pieces(clip: ClipLike) -> tuple[tuple[Piece, ...], tuple[Piece, ...]]:
    """:func:`curve_pieces`, remembered for the last clips played (a play flood compiles once)."""
    with _CACHE_LOCK:
        hit = _CACHE.get(id(clip))
    if hit is not None and hit[0] is clip:
        return hit[1]
    pieces = curve_pieces(clip)
    with _CACHE_LOCK:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[id(clip)] = (clip, pieces)
    return pieces


def _slice(pieces: Sequence[Piece], a: float, b: float, shift: float) -> Iterator[Piece]:
    """The pieces between clip times ``a`` and ``b``, cut there, moved by ``shift`` ms."""
    lo, hi = 0, len(pieces)
    while lo < hi:  # first piece ending after a
        mid = (lo + hi) // 2
        if pieces[mid].t1 <= a:
            lo = mid + 1
        else:
            hi = mid
    for piece in pieces[lo:]:
        if piece.t0 >= b:
            return
        t0, t1 = max(piece.t0, a), min(piece.t1, b)
        if t1 > t0:
            part = piece if (t0, t1) == (piece.t0, piece.t1) else piece.cut(t0, t1)
            yield Piece(part.t0 + shift, part.t1 + shift, part.v0, part.v1)


# --------------------------------------------------------------------------- transients
@dataclass(frozen=True, slots=True)
class _Event:
    u: float  # unrolled ms
    value: float
    decay: float


class _Lookahead:
    """Pieces of one knob with a look-ahead buffer: evaluate the curve ahead, drop what was used."""

    def __init__(self, pieces: Iterator[Piece]) -> None:
        self._source = pieces
        self.buffer: deque[Piece] = deque()
        self.exhausted = False

    def _fill_to(self, u: float) -> None:
        while not self.exhausted and (not self.buffer or self.buffer[-1].t1 <= u):
            piece = next(self._source, None)
            if piece is None:
                self.exhausted = True
            else:
                self.buffer.append(piece)

    def value_at(self, u: float) -> float:
        """The curve at ``u`` (the value just after ``u`` at a jump); past the end, the last value."""
        self._fill_to(u)
        for piece in self.buffer:
            if piece.t0 <= u < piece.t1:
                return piece.at(u)
        return self.buffer[-1].v1 if self.buffer else 0.0

    def end(self, u: float) -> float:
        """``u``, or the end of the curve when it ends before ``u``."""
        self._fill_to(u)
        if self.exhausted and self.buffer and self.buffer[-1].t1 < u:
            return self.buffer[-1].t1
        return u

    def take_until(self, u: float) -> Iterator[Piece]:
        """Yield (and drop) the pieces before ``u``, cutting the one that spans it."""
        self._fill_to(u)
        while self.buffer and self.buffer[0].t0 < u:
            piece = self.buffer.popleft()
            if piece.t1 <= u:
                yield piece
            else:
                yield piece.cut(piece.t0, u)
                self.buffer.appendleft(piece.cut(u, piece.t1))
                return

    def drop_until(self, u: float) -> None:
        for _ in self.take_until(u):
            pass

    def rest(self) -> Iterator[Piece]:
        while self.buffer:
            yield self.buffer.popleft()
        yield from self._source


def _overlay(
    pieces: Iterator[Piece], events: Iterator[_Event], combine: Callable[[float, float], float]
) -> Iterator[Piece]:
    """The curve with transients on top: at each event, ``combine(current, event value)``, then a
    linear glide back to the curve's value at ``u + decay`` (cut short by the next event)."""
    curve = _Lookahead(pieces)
    event = next(events, None)
    carried: tuple[float, float] | None = None  # (u, value) where the previous decay was cut
    while event is not None:
        yield from curve.take_until(event.u)
        if curve.exhausted and not curve.buffer:
            return
        here = carried[1] if carried is not None and carried[0] == event.u else curve.value_at(event.u)
        start = combine(here, event.value)
        target_u = event.u + max(event.decay, 0.0)
        target = curve.value_at(target_u)
        following = next(events, None)
        stop = target_u if following is None else min(target_u, max(following.u, event.u))
        stop = curve.end(stop)
        span = target_u - event.u
        reached = target if span <= 0.0 or stop >= target_u else start + (target - start) * ((stop - event.u) / span)
        if stop > event.u:
            yield Piece(event.u, stop, start, reached)
        curve.drop_until(stop)
        carried = (stop, reached) if stop < target_u else None
        event = following
    yield from curve.rest()


# --------------------------------------------------------------------------- scaling
def _scaled(pieces: Iterator[Piece], scale: float, low: float, high: float) -> Iterator[Piece]:
    """``v * scale`` clamped to [low, high]; a piece crossing a bound is split where it crosses."""
    for piece in pieces:
        v0, v1 = piece.v0 * scale, piece.v1 * scale
        cuts = [piece.t0, piece.t1]
        for bound in (low, high):
            if (v0 - bound) * (v1 - bound) < 0.0:
                cuts.append(piece.t0 + (piece.t1 - piece.t0) * (bound - v0) / (v1 - v0))
        cuts.sort()
        line = Piece(piece.t0, piece.t1, v0, v1)
        for t0, t1 in zip(cuts, cuts[1:]):
            if t1 > t0 or len(cuts) == 2:
                yield Piece(t0, t1, min(max(line.at(t0), low), high), min(max(line.at(t1), low), high))


# --------------------------------------------------------------------------- the timeline
class ClipTimeline:
    """A clip compiled for one playback: knob moves in frame order, and where the clip is at a frame.

    Parameters
    ----------
    clip : Clip
    fs : float
        Engine sample rate.
    start_frame : int
        Stream frame of the clip's time 0.
    gain, rate, loops
        See :func:`check_play_args` (validated here).
    balance_limits : (float, float)
        Live balance range; the balance curve is clamped into it.
    glide_max_s : float
        Longest single glide (longer lines are cut into pieces).

    Attributes
    ----------
    end_frame : int or None
        Frame at which the clip has played to its end (None: loops until stopped).
    """

    def __init__(
        self,
        clip: ClipLike,
        *,
        fs: float,
        start_frame: int = 0,
        gain: float = 1.0,
        rate: float = 1.0,
        loops: float = 1,
        balance_limits: tuple[float, float] = (-math.inf, math.inf),
        glide_max_s: float = 10.0,
    ) -> None:
        self.gain, self.rate, self.loops = check_play_args(gain, rate, loops)
        if not (math.isfinite(fs) and fs > 0):
            raise ParameterError(f"sample rate must be > 0, got {fs!r}")
        self.clip = clip
        self.fs = float(fs)
        self.start_frame = int(start_frame)
        self.balance_limits = (float(balance_limits[0]), float(balance_limits[1]))
        self.glide_max_frames = max(1, int(glide_max_s * self.fs))
        self._frames_per_ms = self.fs / (1000.0 * self.rate)
        duration = float(clip.duration_ms)
        if not (math.isfinite(duration) and duration > 0):
            raise ParameterError(f"clip {clip.name!r}: duration must be > 0 ms, got {duration!r}")
        self.duration_ms = duration
        loop = clip.loop
        if loop is None:
            self.loop_start, self.loop_end = 0.0, duration
        else:
            self.loop_start, self.loop_end = float(loop[0]), float(loop[1])
            if not 0.0 <= self.loop_start < self.loop_end <= duration:
                raise ParameterError(f"clip {clip.name!r}: loop {loop!r} is not inside 0..{duration:g} ms")
        if self.loops != 1 and self.loop_end - self.loop_start < MIN_LOOP_MS:
            raise ParameterError(
                f"clip {clip.name!r}: a loop region of {self.loop_end - self.loop_start:g} ms is too short to repeat "
                f"(at least {MIN_LOOP_MS:g} ms)"
            )
        self._tail = duration - self.loop_end if loop is not None else 0.0
        self.total_ms: float | None = None
        self.end_frame: int | None = None
        if self.loops:
            self.total_ms = self.loop_end + (self.loops - 1) * (self.loop_end - self.loop_start) + self._tail
            self.end_frame = self.frame_of(self.total_ms)

    # ------------------------------------------------------------------ time
    def frame_of(self, u_ms: float) -> int:
        """Stream frame of ``u_ms`` of unrolled clip time after the start."""
        return self.start_frame + int(round(u_ms * self._frames_per_ms))

    def _sections(self) -> Iterator[tuple[float, float, float]]:
        """``(clip_a, clip_b, unrolled start)`` of each section, in order (endless for loops = 0)."""
        yield 0.0, self.loop_end, 0.0
        length = self.loop_end - self.loop_start
        k = 1
        while self.loops == 0 or k < self.loops:
            yield self.loop_start, self.loop_end, self.loop_end + (k - 1) * length
            k += 1
        if self._tail > 0.0:
            yield self.loop_end, self.duration_ms, self.loop_end + (self.loops - 1) * length

    def position(self, frame: int) -> ClipPosition:
        """Where the clip is at stream ``frame`` (clip time, loop pass, repeats left)."""
        u = max(0.0, (frame - self.start_frame) / self._frames_per_ms)
        length = self.loop_end - self.loop_start
        ended = self.end_frame is not None and frame >= self.end_frame
        repeats = self.loops - 1
        if u < self.loop_end:
            return ClipPosition(u, 0, -1 if self.loops == 0 else repeats, ended)
        k = int((u - self.loop_end) // length) + 1 if length > 0 else 1
        if self.loops == 0 or k <= repeats:
            return ClipPosition(
                self.loop_start + (u - self.loop_end - (k - 1) * length),
                k,
                -1 if self.loops == 0 else repeats - k,
                ended,
            )
        tail_u = u - self.loop_end - repeats * length
        return ClipPosition(min(self.loop_end + tail_u, self.duration_ms), -1, 0, ended)

    # ------------------------------------------------------------------ pieces
    def pieces(self, knob: KnobName) -> Iterator[Piece]:
        """One knob's curve in unrolled ms: transients on top, scaled and clamped."""
        curves = _cached_pieces(self.clip)
        index = _KNOBS.index(knob)
        transients = sorted(self.clip.transients, key=lambda tr: tr.t_ms)

        def curve() -> Iterator[Piece]:
            for a, b, shift in self._sections():
                yield from _slice(curves[index], a, b, shift - a)

        def events() -> Iterator[_Event]:
            for a, b, shift in self._sections():
                for tr in transients:
                    if a <= tr.t_ms < b:
                        value = tr.intensity if knob == "intensity" else tr.balance
                        yield _Event(shift + tr.t_ms - a, float(value), float(tr.decay_ms))

        combine: Callable[[float, float], float] = max if knob == "intensity" else (lambda _curve, value: value)
        overlaid = _overlay(curve(), events(), combine) if transients else curve()
        if knob == "intensity":
            return _scaled(overlaid, self.gain, 0.0, 1.0)
        return _scaled(overlaid, 1.0, *self.balance_limits)

    def knob_moves(self, knob: KnobName) -> Iterator[KnobMove]:
        """One knob's engine moves in frame order (a jump and a glide may share a frame, in that order)."""
        for _, move in self._knob_stream(knob):
            if move is not None:
                yield move

    def _knob_stream(self, knob: KnobName) -> Iterator[tuple[int, KnobMove | None]]:
        """``(frame, move)`` in frame order, and ``(end frame, None)`` after every piece.

        The markers let a consumer of an endless loop whose curve is constant stop at a frame
        (there is always a next item), and make :meth:`timed_moves` merge the knobs lazily.
        """
        current: float | None = None
        for piece in self.pieces(knob):
            f0, f1 = self.frame_of(piece.t0), self.frame_of(piece.t1)
            if f1 <= f0:  # shorter than a frame: the knob just arrives at the piece's end
                if current is None or abs(piece.v1 - current) > _SAME:
                    yield f0, KnobMove(f0, knob, piece.v1, 0.0)
                    current = piece.v1
            else:
                if current is None or abs(piece.v0 - current) > _SAME:
                    yield f0, KnobMove(f0, knob, piece.v0, 0.0)
                if abs(piece.v1 - piece.v0) > _SAME:
                    for move in self._glide(f0, f1, piece.v0, piece.v1, knob):
                        yield move.frame, move
                current = piece.v1
            yield f1, None

    def _glide(self, f0: int, f1: int, v0: float, v1: float, knob: KnobName) -> Iterator[KnobMove]:
        n = f1 - f0
        step = self.glide_max_frames
        for a in range(0, n, step):
            b = min(n, a + step)
            value = v1 if b == n else v0 + (v1 - v0) * (b / n)
            yield KnobMove(f0 + a, knob, value, (b - a) / self.fs)

    def timed_moves(self) -> Iterator[tuple[int, KnobMove | None]]:
        """Both knobs merged in frame order: ``(frame, move)``, with ``(frame, None)`` progress markers.

        Every item's frame is at least the previous one's, and an endless clip always has a
        next item, so a consumer can stop at any frame (the live player's look-ahead).
        """
        return heapq.merge(self._knob_stream("balance"), self._knob_stream("intensity"), key=lambda item: item[0])

    def moves(self) -> Iterator[KnobMove]:
        """Both knobs' moves merged in frame order (balance first within a frame). Endless for ``loops = 0``."""
        return (move for _, move in self.timed_moves() if move is not None)
