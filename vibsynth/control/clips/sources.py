"""Clips on the spatial touch sources: a clip drives a source's texture, the mixer spreads it (docs/clips.md).

A clip played on source ``k`` (``/vibsynth/source/{k}/play``) moves that source's intensity and
balance along the compiled clip (:class:`~vibsynth.control.clips.timeline.ClipTimeline`); the
sources' mixer (:mod:`vibsynth.control.spatial.mixer`) then mixes the source onto the layout's
actuators as it does for any texture change. The mixer works in updates (``sources.update_ms``,
10 ms by default) and glides the channels over one update, so on a source the clip is sampled
every update, each sample a timetagged source change at its exact frame, and the channels move
in straight lines between samples: a hold step or a transient's onset is spread over one update.

When the clip ends (or is stopped) the source returns to the texture it had when the clip
started (gliding over the release, in update steps). Texture messages sent to the source while a
clip plays it are overwritten by the clip. One clip per source: a new play replaces it.

The samples are handed to the mixer at most :data:`~vibsynth.control.clips.player.LOOKAHEAD_S`
ahead by the clip player's control thread; a stopped or replaced clip's samples still waiting in
the mixer are turned into no-ops (each carries the generation of its play).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from vibsynth.control.clips.timeline import ClipLike, ClipTimeline, Piece
from vibsynth.errors import ParameterError, ScheduleFullError, VibsynthError

__all__ = ["SourceClips", "NO_SOURCES"]

#: The error of a source play on a server without a layout (no sources).
NO_SOURCES = "sources need a layout (layout: glove, vest-back, wristband or positions; see docs/vr.md)"


class _Curve:
    """One knob's pieces, evaluated at increasing times."""

    def __init__(self, pieces: Iterator[Piece]) -> None:
        self._pieces = pieces
        self._piece: Piece | None = next(pieces, None)
        self._last = 0.0 if self._piece is None else self._piece.v0

    def at(self, u: float) -> float:
        while self._piece is not None and self._piece.t1 <= u:
            self._last = self._piece.v1
            self._piece = next(self._pieces, None)
        if self._piece is None or u < self._piece.t0:
            return self._last
        return self._piece.at(u)


@dataclass
class _SourcePlay:
    timeline: ClipTimeline
    name: str
    generation: int
    restore: tuple[float, float]
    samples: Iterator[tuple[int, float, float]]
    next: tuple[int, float, float] | None
    end_frame: int | None


class SourceClips:
    """The clips playing on the touch sources (driven by the clip player's control thread).

    Parameters
    ----------
    mixer_of : callable
        ``() -> SourceMixer | None``: the running mixer (None: no layout).
    resolve : callable
        ``name -> Clip``.
    fs : float
    limits : KnobLimits
        Live balance range and longest glide.
    lookahead_frames : int
    """

    def __init__(
        self,
        mixer_of: Callable[[], Any],
        resolve: Callable[[str], ClipLike],
        *,
        fs: float,
        limits: Any,
        lookahead_frames: int,
    ) -> None:
        self.mixer_of = mixer_of
        self.resolve = resolve
        self.fs = float(fs)
        self.limits = limits
        self.lookahead_frames = int(lookahead_frames)
        self._lock = threading.RLock()
        self._plays: dict[int, _SourcePlay] = {}
        self._generation: dict[int, int] = {}
        self.refused = 0

    def _mixer(self) -> Any:
        mixer = self.mixer_of()
        if mixer is None:
            raise VibsynthError(NO_SOURCES)
        return mixer

    def _step_frames(self, mixer: Any) -> int:
        return max(1, int(round(float(mixer.update_s) * self.fs)))

    # ------------------------------------------------------------------ requests
    def play(
        self,
        name: str,
        sources: Sequence[int],
        *,
        gain: float = 1.0,
        rate: float = 1.0,
        loops: float = 1,
        start_frame: int,
        now: int,
    ) -> ClipTimeline:
        """Play clip ``name`` on sources (0-based) from ``start_frame``; returns the compiled clip."""
        mixer = self._mixer()
        indices = tuple(sorted({int(k) for k in sources}))
        for k in indices:
            if not 0 <= k < len(mixer.table):
                raise ParameterError(f"source {k + 1} does not exist (sources are 1..{len(mixer.table)})")
        clip = self.resolve(name)
        timeline = ClipTimeline(
            clip,
            fs=self.fs,
            start_frame=start_frame,
            gain=gain,
            rate=rate,
            loops=loops,
            balance_limits=(self.limits.balance_min, self.limits.balance_max),
            glide_max_s=self.limits.glide_max_s,
        )
        with self._lock:
            for k in indices:
                previous = self._plays.get(k)
                restore = previous.restore if previous is not None else mixer.read(_texture_of(k))
                generation = self._generation.get(k, 0) + 1
                self._generation[k] = generation
                samples = self._samples(timeline, self._step_frames(mixer))
                self._plays[k] = _SourcePlay(
                    timeline, str(getattr(clip, "name", name)), generation, restore, samples, None, timeline.end_frame
                )
                self._plays[k].next = next(samples, None)
            self.pump(now)
        return timeline

    def stop(self, sources: Sequence[int] | None, *, release_s: float | None, at_frame: int | None, now: int) -> int:
        """Stop the clips on sources (None = every source); they glide back to their texture. Returns how many."""
        mixer = self._mixer()
        with self._lock:
            indices = sorted(self._plays) if sources is None else [int(k) for k in sources if int(k) in self._plays]
            frame = now if at_frame is None else max(int(at_frame), now)
            for k in indices:
                play = self._plays.pop(k)
                self._generation[k] = self._generation.get(k, 0) + 1
                self._restore(mixer, k, play, frame, now, release_s)
            return len(indices)

    def playing(self, index: int, now: int) -> tuple[str, float, int] | None:
        """``(name, position_ms, loops_left)`` of the clip on source ``index`` (0-based) at frame ``now``, or None."""
        with self._lock:
            play = self._plays.get(index)
        if play is None:
            return None
        position = play.timeline.position(max(now, play.timeline.start_frame))
        return play.name, float(position.clip_ms), int(position.loops_left)

    def names(self) -> dict[int, str]:
        """Source index (0-based) -> the clip playing there."""
        with self._lock:
            return {k: p.name for k, p in self._plays.items()}

    def clear(self) -> None:
        """Forget every clip (panic: the mixer turned the sources off); their waiting samples become no-ops."""
        with self._lock:
            for k in self._plays:
                self._generation[k] = self._generation.get(k, 0) + 1
            self._plays.clear()

    # ------------------------------------------------------------------ the control thread
    def pump(self, now: int) -> int:
        """Hand the mixer the samples due before the look-ahead horizon; act on ends. Returns samples sent."""
        mixer = self.mixer_of()
        if mixer is None:
            return 0
        horizon = now + self.lookahead_frames
        sent = 0
        with self._lock:
            for k, play in list(self._plays.items()):
                while play.next is not None and play.next[0] < horizon:
                    frame, intensity, balance = play.next
                    try:
                        mixer.apply(self._setter(k, play.generation, intensity, balance), at_frame=max(frame, now))
                    except ScheduleFullError:
                        self.refused += 1
                        break
                    sent += 1
                    play.next = next(play.samples, None)
                if play.end_frame is not None and play.next is None and now >= play.end_frame:
                    del self._plays[k]
                    self._restore(mixer, k, play, now, now, None)
        return sent

    # ------------------------------------------------------------------ helpers
    def _samples(self, timeline: ClipTimeline, step: int) -> Iterator[tuple[int, float, float]]:
        """``(frame, intensity, balance)`` every ``step`` frames from the start, and at the end."""
        intensity, balance = _Curve(timeline.pieces("intensity")), _Curve(timeline.pieces("balance"))
        frames_per_ms = self.fs / (1000.0 * timeline.rate)
        end = timeline.end_frame
        frame = timeline.start_frame
        while end is None or frame < end:
            u = (frame - timeline.start_frame) / frames_per_ms
            yield frame, intensity.at(u), balance.at(u)
            frame += step
        u = (end - timeline.start_frame) / frames_per_ms
        yield end, intensity.at(u), balance.at(u)

    def _setter(self, index: int, generation: int, intensity: float, balance: float) -> Callable[[Any, float], None]:
        def update(table: Any, t: float) -> None:
            if self._generation.get(index) == generation:  # a stopped or replaced clip's sample: nothing
                table.set_texture(index, intensity, balance)

        return update

    def _restore(
        self, mixer: Any, index: int, play: _SourcePlay, frame: int, now: int, release_s: float | None
    ) -> None:
        """Glide the source back to the texture it had before the clip, from ``frame`` over ``release_s``."""
        step = self._step_frames(mixer)
        generation = self._generation[index]
        start = play.restore
        current = mixer.read(_texture_of(index))
        span = 0 if not release_s else max(1, int(release_s * self.fs))
        points = max(1, math.ceil(span / step)) if span else 1
        for n in range(1, points + 1):
            w = n / points
            i = current[0] + (start[0] - current[0]) * w
            b = current[1] + (start[1] - current[1]) * w
            at = frame + min(span, n * step) if span else frame
            try:
                mixer.apply(self._setter(index, generation, i, b), at_frame=None if at <= now else at)
            except ScheduleFullError:
                self.refused += 1
                mixer.apply(self._setter(index, generation, start[0], start[1]))  # at once, never stuck
                return


def _texture_of(index: int) -> Callable[[Any, float], tuple[float, float]]:
    def reader(table: Any, now: float) -> tuple[float, float]:
        view = table.view(index, now)
        return float(view.intensity), float(view.balance)

    return reader
