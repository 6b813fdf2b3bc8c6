"""The live clip player: compiled clips handed to the engine a little ahead of time, on a control thread.

``play`` compiles a clip (:mod:`vibsynth.control.clips.timeline`) and submits its first
moves at once; a control thread (:meth:`ClipPlayer.start`) keeps every playing clip's
moves submitted :attr:`ClipPlayer.lookahead_s` ahead of the stream, as timetagged
commands of the controller's ``"clip"`` layer. The engine applies them at their exact
frames; the audio callback never sees a clip, only knob moves, so its per-block work does
not depend on how many clips play.

Channels and precedence
-----------------------
The ``"clip"`` layer sits above the ``"knobs"`` and ``"sources"`` layers of the
:class:`~vibsynth.control.controller.Controller`: while a clip plays on a channel it drives
that channel's knobs; direct knob messages are remembered and play once the clip ends,
when the channel glides back to the layer below (:meth:`Controller.release`).

Each channel plays at most one clip at a time. A play on a channel replaces the clip it
plays; a play timetagged for a later frame lets the current clip play until that frame.
Several plays may be waiting on one channel (at most :data:`MAX_QUEUED_PER_CHANNEL`), each
playing until the next one's start. One play may drive several channels (one command per
move for all of them); a later play on some of them takes those away and the clip goes on
on the others.

Bounds
------
* at most ``channels x (1 + MAX_QUEUED_PER_CHANNEL)`` playbacks exist;
* a playback has at most :data:`MAX_IN_FLIGHT` moves submitted and not yet due, whatever
  its density; the player keeps at most :data:`MAX_QUEUED` commands (a quarter of the
  engine's ``schedule_capacity`` at most) waiting in the engine, cancelled ones included,
  and submits at most :data:`MAX_MOVES_PER_TICK` per tick (the rest follow at the next
  tick): a flood of plays cannot fill the engine's schedule, and the work per tick is bounded;
* a new play submits only its first :data:`START_WINDOW_S` at once;
* a refused submission (the engine's schedule is full) is retried at the next tick and
  counted (``stats.schedule_full``).

Timing: a clip started without a frame starts one engine block after "now" (so its first
move is never late). The clip layer takes a channel over at the exact frame its first clip
starts (one ``drive`` without knob values: the engine's layer switch, in stream order).
The end of a clip (its last frame, or a timetagged stop) is acted on by the control thread,
which wakes up for it: the channel glides back to the layer below within about a block of
that frame, holding the clip's last value until then.

Replacing queued moves: the engine drops a layer's waiting moves per channel
(:meth:`Controller.cancel_scheduled`), including a layer switch still ahead; the player
then submits again what still applies (the moves it keeps until they are due), and a
switch still ahead is asked for again.
"""

from __future__ import annotations

import bisect
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from vibsynth.control import spatial
from vibsynth.control.clips.sources import NO_SOURCES, SourceClips
from vibsynth.control.clips.timeline import ClipLike, ClipPosition, ClipTimeline, KnobMove
from vibsynth.control.controller import check_range
from vibsynth.errors import EngineBusyError, ParameterError, VibsynthError

__all__ = [
    "LAYER",
    "LOOKAHEAD_S",
    "MAX_IN_FLIGHT",
    "MAX_MOVES_PER_TICK",
    "MAX_QUEUED",
    "MAX_QUEUED_PER_CHANNEL",
    "LayeredController",
    "PlayerStats",
    "Playing",
    "ClipPlayer",
]

log = logging.getLogger(__name__)

#: The controller layer clips drive (above "knobs" and "sources").
LAYER = "clip"
#: How far ahead of the stream moves are submitted.
LOOKAHEAD_S = 0.15
#: How often the control thread looks at the clips (it also wakes up for every end).
TICK_S = 0.01
#: Moves one playback may have submitted and not yet due.
MAX_IN_FLIGHT = 256
#: Moves the player submits in one tick, all playbacks together.
MAX_MOVES_PER_TICK = 2048
#: Most clip commands the player keeps waiting in the engine's schedule at once (also those a
#: replacement cancelled: the engine drops them only when their frame comes), at most a
#: quarter of ``engine.schedule_capacity``; a flood of plays cannot fill the schedule.
MAX_QUEUED = 2048
#: A new play submits its moves this far ahead at once (the control thread does the rest), so
#: a play that is replaced at once leaves little behind.
START_WINDOW_S = 0.02
#: Plays that may wait (timetagged for later) on one channel besides the one playing.
MAX_QUEUED_PER_CHANNEL = 16
#: Timeline items (moves and progress markers) one playback may step through per tick.
_MAX_ITEMS_PER_PLAYBACK = 4 * MAX_IN_FLIGHT


class LayeredController(Protocol):
    """What the player needs of :class:`~vibsynth.control.controller.Controller`."""

    @property
    def channels(self) -> int: ...

    @property
    def limits(self) -> Any: ...

    @property
    def engine(self) -> Any: ...

    def drive(
        self,
        layer: str,
        *,
        channels: Sequence[int] | None,
        intensity: float | None = None,
        balance: float | None = None,
        at_frame: int | None = None,
        glide_s: float | None = None,
        source: str = "api",
    ) -> Any: ...

    def release(
        self, layer: str, *, channels: Sequence[int] | None, glide_s: float | None = None, source: str = "api"
    ) -> Any: ...

    def cancel_scheduled(self, layer: str, *, channels: Sequence[int] | None = None) -> Any: ...

    def on_panic(self, callback: Callable[[], None]) -> Any: ...

    def count_error(self, kind: str) -> None: ...


@dataclass
class PlayerStats:
    """Counters of the player (read from any thread)."""

    plays: int = 0
    stops: int = 0
    ended: int = 0
    replaced: int = 0
    moves: int = 0
    schedule_full: int = 0


@dataclass(frozen=True)
class Playing:
    """What plays on one channel now (for ``/status`` and ``get clip``).

    Attributes
    ----------
    name : str
        The clip.
    position : ClipPosition
        Clip time, loop pass and repeats left at the current stream frame.
    gain, rate : float
    loops : int
        As asked (0 = until stopped).
    started : bool
        False while a timetagged start is still ahead (``position`` is then 0).
    """

    name: str
    position: ClipPosition
    gain: float
    rate: float
    loops: int
    started: bool


class _Items:
    """A timeline's ``(frame, move)`` items with one item of look-ahead."""

    def __init__(self, items: Iterator[tuple[int, KnobMove | None]]) -> None:
        self._items = items
        self.head: tuple[int, KnobMove | None] | None = next(items, None)

    def pop(self) -> tuple[int, KnobMove | None]:
        assert self.head is not None
        item, self.head = self.head, next(self._items, None)
        return item


@dataclass(eq=False)
class _Playback:
    """One play of a clip on a set of channels."""

    timeline: ClipTimeline
    name: str
    source: str
    items: _Items
    #: channel -> frame at which this playback stops driving it (a later play starts, or a stop)
    until: dict[int, int | None]
    #: submitted moves not yet due (kept to resubmit them after a cancel on one channel)
    in_flight: deque[KnobMove] = field(default_factory=deque)

    @property
    def start(self) -> int:
        return self.timeline.start_frame

    def channels_at(self, frame: int) -> tuple[int, ...]:
        """The channels this playback drives at ``frame``."""
        return tuple(sorted(c for c, end in self.until.items() if frame >= self.start and (end is None or frame < end)))

    def finish(self, channel: int) -> int | None:
        """The frame at which it stops driving ``channel``: its own end or its cut (None: never)."""
        cut, own = self.until.get(channel), self.timeline.end_frame
        if cut is None:
            return own
        return cut if own is None else min(cut, own)

    def done_at(self) -> int | None:
        """The frame after which it drives nothing (None: endless)."""
        ends = [self.finish(c) for c in self.until]
        if not ends or any(e is None for e in ends):
            return None
        return max(e for e in ends if e is not None)


class ClipPlayer:
    """Plays clips on the channels of a controller's engine (see the module docstring).

    Parameters
    ----------
    controller : Controller
        With controller layers (``drive``, ``release``, ``cancel_scheduled``, ``on_panic``).
    resolve : callable
        ``name -> Clip``; raises :class:`~vibsynth.errors.VibsynthError` for an unknown name
        (:meth:`vibsynth.settings.clips.ClipLibrary.get`).
    lookahead_s : float
        How far ahead moves are submitted.
    tick_s : float
        Longest sleep of the control thread.
    start_margin_frames : int, optional
        How far after the stream position an immediate play starts; default the engine's
        ``max_block`` (one block: the first move is never late).
    clock : callable
        Monotonic seconds (tests).
    """

    def __init__(
        self,
        controller: LayeredController,
        resolve: Callable[[str], ClipLike],
        *,
        lookahead_s: float = LOOKAHEAD_S,
        tick_s: float = TICK_S,
        start_margin_frames: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.controller = controller
        self.engine = controller.engine
        self.resolve = resolve
        self.fs = float(self.engine.fs)
        self.lookahead_frames = max(1, int(lookahead_s * self.fs))
        self.tick_s = float(tick_s)
        margin = start_margin_frames if start_margin_frames is not None else getattr(self.engine, "max_block", 0)
        self.start_margin_frames = max(0, int(margin))
        self.clock = clock
        self.stats = PlayerStats()
        capacity = int(getattr(self.engine, "schedule_capacity", 4 * MAX_QUEUED))
        self.max_queued = max(1, min(MAX_QUEUED, capacity // 4))
        self.start_window_frames = max(1, int(START_WINDOW_S * self.fs))
        self._queued: deque[int] = deque()  # frames of the commands submitted and not yet due
        self._lock = threading.RLock()
        # per channel: playbacks in start order, each driving it until the next one's start
        self._queues: list[list[_Playback]] = [[] for _ in range(controller.channels)]
        self._playbacks: list[_Playback] = []
        self._stops: list[tuple[int, int, float | None]] = []  # (frame, channel, release glide) to act on
        # per channel: frame of the clip layer's takeover in the engine (None: the layer is released there)
        self._takeover: list[int | None] = [None] * controller.channels
        #: clips on the spatial touch sources (control/clips/sources.py)
        self.sources = SourceClips(
            lambda: spatial.mixer_of(controller),
            resolve,
            fs=self.fs,
            limits=controller.limits,
            lookahead_frames=self.lookahead_frames,
        )
        self._wake = threading.Event()
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        controller.on_panic(self._on_panic)

    # ------------------------------------------------------------------ requests
    def play(
        self,
        name: str,
        *,
        channels: Sequence[int] | None = None,
        gain: float = 1.0,
        rate: float = 1.0,
        loops: float = 1,
        at_frame: int | None = None,
        source: str = "api",
    ) -> ClipTimeline:
        """Start clip ``name`` on channels (0-based; None = all), now or at a stream frame.

        Returns
        -------
        timeline : ClipTimeline
            The compiled playback (its ``start_frame`` and ``end_frame``).

        Raises
        ------
        VibsynthError
            Unknown clip (the library's error, with its did-you-mean).
        ParameterError
            Gain, rate or loops out of range, no such channel, or too many plays waiting.
        """
        clip = self.resolve(name)
        chans = self._channels(channels)
        limits = self.controller.limits
        now = int(self.engine.frame_position)
        start = now + self.start_margin_frames if at_frame is None else max(int(at_frame), now)
        timeline = ClipTimeline(
            clip,
            fs=self.fs,
            start_frame=start,
            gain=gain,
            rate=rate,
            loops=loops,
            balance_limits=(limits.balance_min, limits.balance_max),
            glide_max_s=limits.glide_max_s,
        )
        with self._lock:
            for c in chans:
                waiting = sum(1 for p in self._queues[c] if p.start > now)
                if waiting >= MAX_QUEUED_PER_CHANNEL:
                    raise ParameterError(
                        f"channel {c + 1} already has {waiting} clips waiting to start "
                        f"(at most {MAX_QUEUED_PER_CHANNEL})"
                    )
            playback = _Playback(timeline, str(getattr(clip, "name", name)), source, _Items(timeline.timed_moves()), {})
            self._take_over(tuple(c for c in chans if self._takeover[c] is None), start, source)  # may refuse
            self._playbacks.append(playback)
            self._insert(playback, chans, now)
            self.stats.plays += 1
            self._pump(
                playback,
                now,
                MAX_MOVES_PER_TICK,
                horizon=min(start, now + self.lookahead_frames) + self.start_window_frames,
            )
        self._wake.set()
        return timeline

    def stop(
        self,
        *,
        channels: Sequence[int] | None = None,
        release_s: float | None = None,
        at_frame: int | None = None,
        source: str = "api",
        only: ClipTimeline | None = None,
    ) -> int:
        """Stop the clips on channels (None = all), now or at a stream frame; returns how many channels had one.

        The channels glide back to the layer below (their knob state) over ``release_s``
        (None = the channel's glide). A stop at a frame lets the clip play until then and
        drops plays waiting to start after it. With ``only`` (what :meth:`play` returned),
        only the channels where that play is still playing or waiting are stopped (a MIDI
        note-off stops its own clip, not one that took the channel over since).
        """
        chans = self._channels(channels)
        if release_s is not None:
            release_s = check_range("release", release_s, 0.0, self.controller.limits.glide_max_s)
        with self._lock:
            now = int(self.engine.frame_position)
            frame = now if at_frame is None else max(int(at_frame), now)
            stopped = []
            for c in chans:
                queue = self._queues[c]
                if not queue or (only is not None and not any(self._holds(p, c, only, now) for p in queue)):
                    continue
                keep = [p for p in queue if p.start < frame]
                for p in queue:
                    if p.start >= frame:
                        p.until.pop(c, None)
                if keep:
                    last = keep[-1]
                    end = last.until.get(c)
                    last.until[c] = frame if end is None else min(end, frame)
                self._queues[c] = keep
                stopped.append(c)
            if not stopped:
                return 0
            self.stats.stops += 1
            chans = tuple(stopped)
            if frame <= now:
                self.controller.cancel_scheduled(LAYER, channels=chans)
                self.controller.release(LAYER, channels=chans, glide_s=release_s, source=source)
                for c in chans:
                    self._takeover[c] = None
            else:
                self._reset(chans, now)
                self._stops.extend((frame, c, release_s) for c in chans)
            self._forget_idle()
        self._wake.set()
        return len(stopped)

    @staticmethod
    def _holds(p: _Playback, channel: int, timeline: ClipTimeline, now: int) -> bool:
        """Is ``p`` the play of ``timeline``, still playing or waiting on ``channel``?"""
        finish = p.finish(channel)
        return p.timeline is timeline and (finish is None or finish > now)

    def play_source(
        self,
        name: str,
        *,
        sources: Sequence[int] | None = None,
        gain: float = 1.0,
        rate: float = 1.0,
        loops: float = 1,
        at_frame: int | None = None,
    ) -> ClipTimeline:
        """Play clip ``name`` on spatial sources (0-based; None = every source), now or at a stream frame.

        Raises
        ------
        VibsynthError
            No layout (no sources), unknown clip, arguments out of range, no such source.
        """
        now = int(self.engine.frame_position)
        start = now + self.start_margin_frames if at_frame is None else max(int(at_frame), now)
        every = range(len(self._mixer_table()))
        timeline = self.sources.play(
            name, every if sources is None else sources, gain=gain, rate=rate, loops=loops, start_frame=start, now=now
        )
        self.stats.plays += 1
        self._wake.set()
        return timeline

    def stop_source(
        self, *, sources: Sequence[int] | None = None, release_s: float | None = None, at_frame: int | None = None
    ) -> int:
        """Stop the clips on spatial sources (None = every source); they glide back to their texture."""
        if release_s is not None:
            release_s = check_range("release", release_s, 0.0, self.controller.limits.glide_max_s)
        stopped = self.sources.stop(
            sources, release_s=release_s, at_frame=at_frame, now=int(self.engine.frame_position)
        )
        self.stats.stops += 1 if stopped else 0
        return stopped

    def _mixer_table(self) -> Any:
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            raise VibsynthError(NO_SOURCES)
        return mixer.table

    def playing(self, channel: int) -> Playing | None:
        """What plays on ``channel`` (0-based) now, or the next clip waiting to start; None when idle."""
        with self._lock:
            now = int(self.engine.frame_position)
            current = None
            for p in self._queues[self._channels([channel])[0]]:
                finish = p.finish(channel)
                if p.start <= now and (finish is None or now < finish):
                    current = p
                elif p.start > now and current is None:
                    current = p
                    break
            if current is None:
                return None
            t = current.timeline
            started = current.start <= now
            position = t.position(now) if started else t.position(t.start_frame)
            return Playing(current.name, position, t.gain, t.rate, t.loops, started)

    # ------------------------------------------------------------------ the control thread
    def start(self) -> None:
        """Start the control thread."""
        if self._thread is not None:
            return
        self._halt.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-clips", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the control thread (clips still playing are stopped first)."""
        if self._thread is not None:
            try:
                self.stop(release_s=None, source="shutdown")
            except VibsynthError as exc:
                log.debug("stopping clips at shutdown: %s", exc)
            self._halt.set()
            self._wake.set()
            self._thread.join(timeout=2.0)
            self._thread = None

    def _run(self) -> None:
        while not self._halt.is_set():
            try:
                delay = self.tick()
            except Exception:  # keep playing the other clips; the error is logged once per tick
                log.exception("clip player tick failed")
                delay = self.tick_s
            self._wake.wait(delay)
            self._wake.clear()

    def tick(self) -> float:
        """Submit due moves, act on ends and stops; returns how long the thread may sleep (s)."""
        with self._lock:
            now = int(self.engine.frame_position)
            budget = MAX_MOVES_PER_TICK
            for playback in list(self._playbacks):
                budget -= self._pump(playback, now, budget)
            self._act_on_stops(now)
            self._act_on_ends(now)
            wake = [f for f, _, _ in self._stops] + [
                e for p in self._playbacks if (e := p.done_at()) is not None and e > now
            ]
            idle = not self._playbacks and not self._stops
        self.sources.pump(now)
        idle = idle and not self.sources.names()
        if idle:
            return 1.0
        delay = self.tick_s
        if wake:
            delay = min(delay, max(0.0, (min(wake) - now) / self.fs))
        return delay

    # ------------------------------------------------------------------ internals (lock held)
    def _channels(self, channels: Sequence[int] | None) -> tuple[int, ...]:
        if channels is None:
            return tuple(range(self.controller.channels))
        out = tuple(sorted({int(c) for c in channels}))
        for c in out:
            if not 0 <= c < self.controller.channels:
                raise ParameterError(f"channel {c + 1} does not exist (channels are 1..{self.controller.channels})")
        if not out:
            raise ParameterError("no channel selected")
        return out

    def _insert(self, playback: _Playback, chans: tuple[int, ...], now: int) -> None:
        """Put ``playback`` on ``chans``: it plays from its start until the next waiting play's start.

        A play with the same start is replaced; the one before is cut at this start, and what
        was already queued in the engine on those channels is submitted again as it now applies.
        """
        start = playback.start
        touched = []
        for c in chans:
            queue = self._queues[c]
            if queue:
                touched.append(c)
            for p in queue:
                if p.start == start:
                    p.until.pop(c, None)
                    self.stats.replaced += 1
            earlier = [p for p in queue if p.start < start]
            later = [p for p in queue if p.start > start]
            if earlier:
                prev = earlier[-1]
                end = prev.until.get(c)
                if end is None or end > start:
                    prev.until[c] = start
                    self.stats.replaced += 1
            playback.until[c] = later[0].start if later else None
            self._queues[c] = [*earlier, playback, *later]
        if touched:
            self._reset(tuple(touched), now)
        self._forget_idle()

    def _take_over(self, chans: tuple[int, ...], frame: int, source: str) -> None:
        """The clip layer takes ``chans`` over at ``frame`` (a drive without knob values: the layer switch)."""
        if chans:
            self.controller.drive(LAYER, channels=chans, at_frame=frame, source=source)
            self._note_queued(frame)
            for c in chans:
                self._takeover[c] = frame

    def _reset(self, chans: tuple[int, ...], now: int) -> None:
        """Drop the clip layer's queued moves on ``chans`` and submit again what still applies there.

        Where the layer's takeover is still ahead in the engine it was dropped too: the layer
        is released there (it drives nothing yet, so nothing changes) and takes over again at
        the first start still waiting.
        """
        pending = tuple(c for c in chans if (t := self._takeover[c]) is None or t >= now)
        if pending:
            self.controller.release(LAYER, channels=pending, source="clip")
        self.controller.cancel_scheduled(LAYER, channels=chans)
        starts: dict[int, list[int]] = {}
        for c in pending:
            self._takeover[c] = None
            if self._queues[c]:
                starts.setdefault(min(p.start for p in self._queues[c]), []).append(c)
        for frame, group in starts.items():
            self._take_over(tuple(group), frame, "clip")
        for p in self._playbacks:
            for move in p.in_flight:
                if move.frame < now:
                    continue
                targets = tuple(c for c in p.channels_at(move.frame) if c in chans)
                if targets:
                    self._submit(p, move, targets)

    def _pump(self, playback: _Playback, now: int, budget: int, horizon: int | None = None) -> int:
        """Submit the playback's moves due before the look-ahead horizon; returns how many were submitted."""
        flight = playback.in_flight
        while flight and flight[0].frame < now:
            flight.popleft()
        queued = self._queued
        while queued and queued[0] < now:
            queued.popleft()
        budget = min(budget, self.max_queued - len(queued))
        if horizon is None:
            horizon = now + self.lookahead_frames
        items = playback.items
        sent = steps = 0
        while (
            items.head is not None
            and items.head[0] < horizon
            and sent < budget
            and len(flight) < MAX_IN_FLIGHT
            and steps < _MAX_ITEMS_PER_PLAYBACK
        ):
            steps += 1
            frame, move = items.head
            targets = playback.channels_at(frame) if move is not None else ()
            if targets:
                if not self._submit(playback, move, targets):  # type: ignore[arg-type]  # move is set
                    break  # the engine refused: try again at the next tick
                flight.append(move)  # type: ignore[arg-type]
                sent += 1
            items.pop()
        return sent

    def _submit(self, playback: _Playback, move: KnobMove, chans: tuple[int, ...]) -> bool:
        try:
            self.controller.drive(
                LAYER,
                channels=chans,
                intensity=move.value if move.knob == "intensity" else None,
                balance=move.value if move.knob == "balance" else None,
                at_frame=move.frame,
                glide_s=move.glide_s,
                source=playback.source,
            )
        except EngineBusyError as exc:  # ScheduleFullError included
            self.stats.schedule_full += 1
            self.controller.count_error("clip.schedule_full")
            log.debug("clip %s: %s", playback.name, exc)
            return False
        self.stats.moves += 1
        self._note_queued(move.frame)
        return True

    def _note_queued(self, frame: int) -> None:
        """Remember a command waiting in the engine until ``frame`` (kept in frame order)."""
        queued = self._queued
        if not queued or frame >= queued[-1]:
            queued.append(frame)
        else:
            queued.insert(bisect.bisect_right(queued, frame), frame)

    def _act_on_stops(self, now: int) -> None:
        due = [s for s in self._stops if s[0] <= now]
        if not due:
            return
        self._stops = [s for s in self._stops if s[0] > now]
        by_release: dict[float | None, list[int]] = {}
        for _, c, release in due:
            if not any(c in p.channels_at(now) for p in self._queues[c]):  # nothing took over since
                by_release.setdefault(release, []).append(c)
        for release, chans in by_release.items():
            self.controller.release(LAYER, channels=tuple(chans), glide_s=release, source="clip stop")
            for c in chans:
                self._takeover[c] = None

    def _act_on_ends(self, now: int) -> None:
        """Release channels whose clip played to its end and drop finished playbacks.

        A clip that ends before the next waiting one starts hands the channel back in
        between; the next one then takes it over again at its start.
        """
        ended: list[int] = []
        for c, queue in enumerate(self._queues):
            while queue:
                head = queue[0]
                finish = head.finish(c)
                if finish is None or now < finish:
                    break
                queue.pop(0)
                cut, own = head.until.pop(c, None), head.timeline.end_frame
                if own is not None and (cut is None or own < cut):  # it played to its own end
                    ended.append(c)
        if ended:
            self.stats.ended += 1
            chans = tuple(ended)
            self.controller.release(LAYER, channels=chans, glide_s=None, source="clip end")
            for c in chans:
                self._takeover[c] = None
            waiting = tuple(c for c in chans if self._queues[c])
            if waiting:
                self._reset(waiting, now)
        self._forget_idle()

    def _forget_idle(self) -> None:
        self._playbacks = [p for p in self._playbacks if p.until]

    def _on_panic(self) -> None:
        """Panic: every clip stops at once (the controller has already silenced the engine and
        released every layer; moves a tick submitted meanwhile are dropped here)."""
        with self._lock:
            active = bool(self._playbacks)
            for p in self._playbacks:
                p.until.clear()
            self._playbacks.clear()
            self._queues = [[] for _ in self._queues]
            self._stops.clear()
            self._takeover = [None] * len(self._takeover)
            self.sources.clear()
            if active:
                self.controller.cancel_scheduled(LAYER)
                self.controller.release(LAYER, channels=None, glide_s=0.0, source="panic")
