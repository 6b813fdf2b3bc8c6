"""The sources' mixer: a control thread that turns the sources into channel knobs, at a bounded rate.

Whenever a source changes (and every ``update_s`` while one moves), the mixer takes each on
source where it will be one update later, weighs it on every actuator of the layout with its
roll-off law, mixes the sources per actuator in the perceptual model
(:func:`vibsynth.dsp.spatial.mix_sources`) and drives the channels through the controller's
``sources`` layer (:meth:`~vibsynth.control.controller.Controller.drive`), gliding over one
update, so the knobs move as straight lines between updates and arrive where the sources are.

Precedence (the controller's layers): clip > sources > direct knobs. A channel that an on source
reaches (weight > 0) follows the sources' mix; a channel no on source reaches is released and
glides back to its direct knobs, which were remembered meanwhile.

Bounded work whatever arrives: a change only marks the mix dirty (a flood of positions
coalesces into the next update: at most one mix per ``update_s``); timetagged changes wait in
a heap of at most ``schedule_capacity`` entries (more are refused with
:class:`~vibsynth.errors.ScheduleFullError`) and are applied at their stream frame, the
channels driven at that exact frame.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from vibsynth.control import spatial
from vibsynth.control.controller import Controller
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.spatial.sources import SourceTable, SourceView
from vibsynth.dsp.intensity import knob_to_level_db, level_db_to_knob
from vibsynth.dsp.spatial import SpatialLayout, TextureSpectra, mix_sources
from vibsynth.errors import ScheduleFullError, VibsynthError
from vibsynth.settings.layouts import Layout

__all__ = ["SourceMixer", "Update", "LAYER", "SOURCE"]

log = logging.getLogger(__name__)

#: The controller layer the mixer drives.
LAYER = "sources"
#: ``source`` of the mixer's knob moves (shown to /notify subscribers).
SOURCE = "sources"
#: A change applied to the table at a time: ``update(table, t)``.
Update = Callable[[SourceTable, float], None]

#: Most mixes for timetagged changes in one step; later ones due in the same step share the last.
_MAX_TIMED_MIXES = 16
#: A mix due within this much is made now (the clock's and the timer's granularity).
_EARLY_S = 1e-4
#: Knob changes smaller than this are not sent again.
_EPSILON = 1e-6


class SourceMixer:
    """Up to 16 touch sources mixed onto a layout, driving the channels (a control server).

    Parameters
    ----------
    controller : Controller
    layout : Layout
        The actuators' channels and positions.
    spectra : TextureSpectra
        The perceptual model of the textures (built from the engine's basis).
    table : SourceTable
        The sources (validated setters; defaults and limits).
    update_s : float
        Mix period while something moves (and the shortest time between two mixes).
    schedule_capacity : int
        Most timetagged changes waiting at once.
    ceiling_db, range_db : float
        The intensity knob's mapping (``knobs.ceiling_db``, ``knobs.range_db``).
    speed_curve : SpeedCurve
        Speed (mm/s) -> intensity for sources with ``speed`` on.
    clock : callable
        Monotonic seconds (injectable for tests).
    """

    name = "sources"

    def __init__(
        self,
        controller: Controller,
        layout: Layout,
        spectra: TextureSpectra,
        table: SourceTable,
        *,
        update_s: float = 0.01,
        schedule_capacity: int = 1024,
        ceiling_db: float = -40.0,
        range_db: float = 40.0,
        speed_curve: SpeedCurve | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.controller = controller
        self.layout = layout
        self.geometry = SpatialLayout(layout.coordinates)
        self.spectra = spectra
        self.table = table
        self.update_s = float(update_s)
        self.schedule_capacity = int(schedule_capacity)
        self.ceiling_db, self.range_db = float(ceiling_db), float(range_db)
        self.speed_curve = speed_curve or SpeedCurve([[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]])
        self.clock = clock
        self.mixes = 0
        self.errors = 0
        self._cond = threading.Condition()
        self._dirty = False
        self._moving = False
        self._last_mix = -math.inf
        self._schedule: list[tuple[int, int, Update]] = []
        self._seq = itertools.count()
        self._driven: dict[int, tuple[float, float]] = {}
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._unsubscribe_panic: Callable[[], None] | None = None

    # ------------------------------------------------------------------ the adapters' side
    def apply(self, update: Update, *, at_frame: int | None = None) -> None:
        """Apply a (validated) change to the sources now, or at a stream frame.

        Raises
        ------
        ScheduleFullError
            ``schedule_capacity`` timetagged changes are already waiting (nothing changes).
        """
        with self._cond:
            if at_frame is None:
                update(self.table, self.clock())
                self._dirty = True
            else:
                if len(self._schedule) >= self.schedule_capacity:
                    raise ScheduleFullError(
                        f"{self.schedule_capacity} timetagged source messages are already waiting "
                        "(sources.schedule_capacity); message refused"
                    )
                heapq.heappush(self._schedule, (int(at_frame), next(self._seq), update))
            self._cond.notify()

    def read(self, reader: Callable[[SourceTable, float], Any]) -> Any:
        """Call ``reader(table, now)`` under the lock (queries)."""
        with self._cond:
            return reader(self.table, self.clock())

    @property
    def pending(self) -> int:
        """Timetagged changes waiting."""
        with self._cond:
            return len(self._schedule)

    def driven(self) -> dict[int, tuple[float, float]]:
        """The channels the sources drive (0-based) and the (intensity, balance) last sent."""
        with self._cond:
            return dict(self._driven)

    # ------------------------------------------------------------------ control server
    def start(self) -> None:
        """Start the mixer thread and make the mixer findable (:func:`vibsynth.control.spatial.mixer_of`)."""
        if self._thread is not None:
            return
        self._stopping = False
        self._unsubscribe_panic = self.controller.on_panic(self._on_panic)
        self._thread = threading.Thread(target=self._run, name="vibsynth-sources", daemon=True)
        self._thread.start()
        spatial.attach(self.controller, self)

    def stop(self) -> None:
        """Stop the thread and hand every driven channel back to its direct knobs (idempotent)."""
        spatial.detach(self.controller, self)
        with self._cond:
            self._stopping = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._unsubscribe_panic is not None:
            self._unsubscribe_panic()
            self._unsubscribe_panic = None
        with self._cond:
            channels, self._driven = sorted(self._driven), {}
        if channels:
            self._release(channels, None)

    def describe(self) -> str:
        """One line for the start-up banner."""
        return f"sources: {len(self.table)} on {self.layout.describe()}, mixed every {1000 * self.update_s:g} ms"

    # ------------------------------------------------------------------ the thread
    def _run(self) -> None:
        while True:
            with self._cond:
                wait = self._wait_s(self.clock())
                if wait is None or wait > 0:
                    self._cond.wait(wait)
                if self._stopping:
                    return
            try:
                self.step()
            except Exception:  # never let the thread die: count, log, go on
                self.errors += 1
                log.exception("sources: mixing failed")
                time.sleep(self.update_s)

    def _wait_s(self, now: float) -> float | None:
        """With the lock held: how long to sleep before the next step (None = until notified)."""
        waits: list[float] = []
        if self._dirty or self._moving:
            waits.append(self._last_mix + self.update_s - now)
        if self._schedule:
            engine = self.controller.engine
            ahead = (self._schedule[0][0] - engine.frame_position) / float(engine.fs) - self.update_s
            waits.append(min(ahead, 0.5))  # frames and the clock may drift: look again
        return max(0.0, min(waits)) if waits else None

    def step(self) -> None:
        """Apply the timetagged changes that are due and mix when something changed or moves."""
        now = self.clock()
        engine = self.controller.engine
        frame_now = int(engine.frame_position)
        horizon = frame_now + int(round(self.update_s * float(engine.fs)))
        with self._cond:
            due: list[tuple[int, int, Update]] = []
            while self._schedule and self._schedule[0][0] <= horizon:
                due.append(heapq.heappop(self._schedule))
        if due:
            frames = sorted({frame for frame, _, _ in due})
            if len(frames) > _MAX_TIMED_MIXES:  # bounded: the latest ones share one mix
                frames = frames[: _MAX_TIMED_MIXES - 1] + [frames[-1]]
            start = 0
            for i, frame in enumerate(frames):
                last = i == len(frames) - 1
                stop = len(due) if last else next(j for j in range(start, len(due)) if due[j][0] > frame)
                at = now + (frame - frame_now) / float(engine.fs)
                with self._cond:
                    for _, _, update in due[start:stop]:
                        update(self.table, at)
                self._mix(at, at_frame=frame if frame > frame_now else None)
                start = stop
            return
        with self._cond:
            if not (self._dirty or self._moving) or now < self._last_mix + self.update_s - _EARLY_S:
                return
        self._mix(now)

    # ------------------------------------------------------------------ mixing
    def _mix(self, t: float, *, at_frame: int | None = None) -> None:
        """Mix the sources as they will be one update after ``t`` and drive the channels."""
        with self._cond:
            views = self.table.views(t + self.update_s, t)
            moving, was_moving = any(v.moving for v in views), self._moving
            self._dirty, self._moving, self._last_mix = False, moving, t
            previous = dict(self._driven)
        targets = self.targets([v for v in views if v.on])
        glide = self.update_s if (moving or was_moving) else None
        changed: dict[tuple[float, float], list[int]] = {}
        for channel, values in targets.items():
            old = previous.get(channel)
            if old is None or abs(old[0] - values[0]) > _EPSILON or abs(old[1] - values[1]) > _EPSILON:
                changed.setdefault(values, []).append(channel)
        for (intensity, balance), channels in changed.items():
            try:
                self.controller.drive(
                    LAYER,
                    channels=channels,
                    intensity=intensity,
                    balance=balance,
                    at_frame=at_frame,
                    glide_s=glide,
                    source=SOURCE,
                )
            except VibsynthError as exc:  # e.g. the engine's schedule is full: count, keep the old value
                self._count(exc)
                for c in channels:
                    targets[c] = previous.get(c, targets[c])
        gone = sorted(set(previous) - set(targets))
        if gone:
            self._release(gone, at_frame)
        with self._cond:
            self._driven = targets
            self.mixes += 1

    def targets(self, active: Sequence[SourceView]) -> dict[int, tuple[float, float]]:
        """(intensity knob, balance) of every channel the on sources reach (0-based channel -> knobs).

        Parameters
        ----------
        active : sequence of SourceView
            The on sources, where they are.
        """
        if not active:
            return {}
        weights = np.stack([self.geometry.weights(v.rolloff, v.position, v.radius) for v in active])
        knobs = [self._knobs_of(v) for v in active]
        levels = [knob_to_level_db(k, ceiling_db=self.ceiling_db, range_db=self.range_db) for k, _ in knobs]
        mix = mix_sources(weights, levels, [b for _, b in knobs], self.spectra)
        limits = self.table.defaults.limits
        out: dict[int, tuple[float, float]] = {}
        for j, channel in enumerate(self.layout.channels):
            if not np.any(weights[:, j] > 0):
                continue
            level = float(mix.level_db[j])
            intensity = 0.0 if level == -math.inf else level_db_to_knob(level, **self._mapping)
            heard = {knobs[i][1] for i in np.flatnonzero(weights[:, j] > 0) if levels[i] > -math.inf}
            if len(heard) == 1:  # one spectrum shape: the mix has exactly its balance (not rounded by the basis)
                balance = heard.pop()
            elif heard:
                balance = float(mix.balance[j])
            else:  # reached, but silent: the strongest source's balance
                balance = knobs[int(np.argmax(weights[:, j]))][1]
            out[channel] = (
                round(min(max(intensity, 0.0), 1.0), 9),
                round(min(max(balance, limits.balance_min), limits.balance_max), 9),
            )
        return out

    @property
    def _mapping(self) -> dict[str, float]:
        return {"ceiling_db": self.ceiling_db, "range_db": self.range_db}

    def _knobs_of(self, view: SourceView) -> tuple[float, float]:
        """A source's (intensity, balance), from its speed when it has ``speed`` on."""
        if not view.speed:
            return view.intensity, view.balance
        limits = self.table.defaults.limits
        curve = self.speed_curve
        balance = view.balance + curve.balance_shift(view.speed_mm_s)
        return curve.intensity(view.speed_mm_s), min(max(balance, limits.balance_min), limits.balance_max)

    def _release(self, channels: Iterable[int], at_frame: int | None) -> None:
        try:
            self.controller.release(LAYER, channels=list(channels), at_frame=at_frame, source=SOURCE)
        except VibsynthError as exc:
            self._count(exc)

    def _count(self, exc: VibsynthError) -> None:
        self.errors += 1
        self.controller.count_error("sources.drive")
        log.debug("sources: %s", exc)

    def _on_panic(self) -> None:
        """Panic: every source off, timetagged changes dropped (the controller released the channels)."""
        with self._cond:
            self.table.all_off()
            self._schedule.clear()
            self._driven = {}
            self._dirty = self._moving = False
