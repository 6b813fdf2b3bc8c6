"""The live follower: a worker thread that reads an input ring, tracks it, and drives the knobs.

Per step (every ``poll_s``, about half a JACK period) the worker reads what waits in the
:class:`~vibsynth.engine.input_ring.InputRing`, at most ``max_block_s`` of it (bounded work per
step), mixes each route's input channels, runs the route's
:class:`~vibsynth.dsp.follow.Tracker` and submits the newest frame as an ordinary controller
move on the ``follow`` layer (:meth:`~vibsynth.control.controller.Controller.drive`), gliding
over one hop so the knob moves as straight lines between frames (no zipper noise). A route to a
touch source sets the source's texture through the spatial mixer instead; with ``pan`` its two
inputs' level difference also places the source between two points of the layout
(:mod:`~vibsynth.control.follow.pan`).

Precedence (the controller's layers, low to high): knobs < follow < sources < clip. A channel
that follows ignores direct knob moves (they are remembered and play when follow is turned off
on it: ``/vibsynth/ch/{n}/follow 0``); a touch source reaching the channel, or a clip playing on
it, beats follow, and follow takes the channel back when they end. Panic turns follow off on
every route.

A worker that falls behind (more than ``max_lag_s`` of input waiting) drops the stale input and
counts it (:attr:`Follower.stale_frames`) instead of lagging. An input that is lost (its state
``lost``/``retrying``/``ended``/``closed``, or no frame for ``loss_timeout_s``) is reported in
the status; the output holds its last texture or fades out over ``follow.fade_s``
(``follow.on_loss``); when frames flow again the trackers restart and follow resumes.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.control import spatial
from vibsynth.control.controller import Controller, check_range
from vibsynth.control.follow.pan import StereoPan
from vibsynth.control.follow.routes import LiveValues, RouteSpec, default_gate_db, plan_routes, route_params
from vibsynth.control.follow.transients import TransientEnvelope
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.follow import FOCUSES, Tracker
from vibsynth.dsp.follow.onsets import FULL_STRENGTH_DB, ONSET_SCALE_FLOOR
from vibsynth.engine.inputs import InputSource
from vibsynth.errors import ParameterError, VibsynthError
from vibsynth.settings.models import bounds_of
from vibsynth.settings.models_config import Knobs
from vibsynth.settings.models_follow import Follow

__all__ = ["LAYER", "SOURCE", "Follower", "RouteView", "LOST_STATES", "HISTORY_POINTS", "HISTORY_STEP_S"]

log = logging.getLogger(__name__)

#: The controller layer follow drives.
LAYER = "follow"
#: ``source`` of follow's knob moves (shown to /notify subscribers).
SOURCE = "follow"
#: Input states that mean no frames are coming.
LOST_STATES = frozenset({"lost", "retrying", "ended", "closed"})
#: The trace the studio draws: one point per HISTORY_STEP_S of input, the newest HISTORY_POINTS.
HISTORY_STEP_S = 0.02
HISTORY_POINTS = 500
#: Knob changes smaller than these are not sent again (0.04 dB of intensity at the default range).
_EPS_INTENSITY = 1e-3
_EPS_BALANCE = 5e-3
#: A panned source is moved again when its place between the two points changed by more than this.
_EPS_PAN = 5e-3
#: The input's status (device state, meters) is read at most this often.
_STATUS_EVERY_S = 0.05
#: Level reported when nothing was tracked yet (dB).
FLOOR_DB = -200.0


@dataclass(frozen=True)
class RouteView:
    """What one route does now (for status, the studio and tests)."""

    label: str
    kind: str
    index: int
    on: bool
    level_db: float
    gate: bool
    intensity: float
    balance: float
    mode: str
    focus: str
    #: A panned source's place between ``pan.left`` (0) and ``pan.right`` (1); None without pan.
    pan: float | None = None


@dataclass
class _Route:
    spec: RouteSpec
    tracker: Tracker
    envelope: TransientEnvelope
    pan: StereoPan | None = None
    pan_sent: float | None = None
    on: bool = True
    sent: tuple[float, float] | None = None
    level_db: float = FLOOR_DB
    gate: bool = False
    intensity: float = 0.0
    balance: float = 0.0
    next_point: int = 0
    history: deque[tuple[float, float, float, float, bool]] = field(
        default_factory=lambda: deque(maxlen=HISTORY_POINTS)
    )


class Follower:
    """Follow an input on the controller's ``follow`` layer (see the module notes).

    Parameters
    ----------
    controller : Controller
    source : InputSource
        Opened by :meth:`start` (or already open); its ring is read here only.
    follow : Follow
        The typed ``follow:`` section.
    knobs : Knobs
        The intensity mapping (``ceiling_db``, ``range_db``) the tracker maps levels through.
    basis : Basis
        The engine's basis (V1, balance units).
    transient_decay_ms : float
        Decay of a transient (``clips.transient_decay_ms``).
    poll_s : float
        Worker period.
    max_lag_s, max_block_s : float
        Input waiting beyond ``max_lag_s`` is dropped (counted); a step tracks at most ``max_block_s``.
    loss_timeout_s : float
        No frame for this long while the input says it is open counts as lost.
    clock : callable
        Monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        controller: Controller,
        source: InputSource,
        follow: Follow,
        *,
        knobs: Knobs,
        basis: Basis,
        transient_decay_ms: float = 40.0,
        poll_s: float = 0.001,
        max_lag_s: float = 0.05,
        max_block_s: float = 0.02,
        loss_timeout_s: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.controller = controller
        self.source = source
        self.follow = follow
        self.knobs = knobs
        self.basis = basis
        self.transient_decay_s = float(transient_decay_ms) / 1000.0
        self.poll_s, self.max_lag_s, self.max_block_s = float(poll_s), float(max_lag_s), float(max_block_s)
        self.loss_timeout_s = float(loss_timeout_s)
        self.clock = clock
        self.live = LiveValues.of(follow)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._routes: list[_Route] = []
        self._pending_params = False
        self._unsubscribe_panic: Callable[[], None] | None = None
        self._status: dict[str, Any] = {}
        self._status_at = -math.inf
        self._last_data = -math.inf
        self._had_data = False
        self._started_at = -math.inf
        self.lost = False
        #: Input frames dropped because the worker fell behind, and how often it did.
        self.stale_frames = 0
        self.stale_drops = 0
        #: Frames that arrived while the input said it was lost (not a recovery: dropped).
        self.stray_frames = 0
        self.losses = 0
        self.recoveries = 0
        self.steps = 0
        self.errors = 0
        self.submitted = 0

    # ------------------------------------------------------------------ life cycle
    def prepare(self) -> None:
        """Open the input (if needed) and build one tracker per route (raises ConfigError, DeviceError)."""
        ring = self.source.ring
        specs = plan_routes(self.follow, self.controller.channels, ring.channels)
        with self._lock:
            self._routes = [self._make_route(spec) for spec in specs]
        self._started_at = self._last_data = self.clock()
        if self._unsubscribe_panic is None:
            self._unsubscribe_panic = self.controller.on_panic(self._on_panic)

    def _make_route(self, spec: RouteSpec) -> _Route:
        limits = self.controller.limits
        tracker = Tracker(
            fs=self.source.fs,
            params=route_params(self.follow, self.live, spec.route),
            basis=self.basis,
            ceiling_db=self.knobs.ceiling_db,
            range_db=self.knobs.range_db,
            balance_limits=(limits.balance_min, limits.balance_max),
        )
        pan = spec.route.pan
        stereo = None if pan is None else StereoPan(self.source.fs, tracker.params, pan)
        return _Route(spec, tracker, TransientEnvelope(self.source.fs, self.transient_decay_s), stereo)

    def start(self) -> None:
        """Open the input, build the routes and start the worker."""
        self.source.open()
        self.prepare()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-follow", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the worker, release the channels (knobs take over) and close the input."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)
        if self._unsubscribe_panic is not None:
            self._unsubscribe_panic()
            self._unsubscribe_panic = None
        with self._lock:
            channels = [r.spec.index for r in self._routes if r.spec.kind == "channel"]
        if channels:
            self.controller.release(LAYER, channels=channels, source=SOURCE)
        self.source.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                busy = self.step()
            except Exception:  # noqa: BLE001 - the worker never dies; counted and logged once per kind
                self.errors += 1
                if self.errors == 1:
                    log.exception("follow: a step failed (counted; follow goes on)")
                busy = False
            if not busy:
                self._stop.wait(self.poll_s)

    # ------------------------------------------------------------------ one step
    def step(self) -> bool:
        """Track what waits in the ring and drive the knobs; True when more input waits (call again).

        Never blocks; the worker calls it every ``poll_s``, tests call it directly.
        """
        now = self.clock()
        self.steps += 1
        self._apply_params()
        ring = self.source.ring
        fs = ring.fs
        waiting = ring.available
        if waiting > self.max_lag_s * fs:
            keep = int(self.max_block_s * fs)
            dropped = ring.skip(waiting - keep)
            self.stale_frames += dropped
            self.stale_drops += 1
        block = ring.read(max(1, int(self.max_block_s * fs)))
        state = self._input_state(now)
        if block.shape[0] and self.lost and state in LOST_STATES:
            # A stream being torn down may still deliver a stray block (PortAudio on a dead JACK
            # server does, while the output retries): it is no recovery; dropped and counted.
            self.stray_frames += block.shape[0]
            return False
        if block.shape[0]:
            self._last_data = now
            self._had_data = True
            if self.lost:
                self._recover()
            self._track(block)
            return ring.available > 0
        # a stall counts once frames have flowed (a file waits for the output clock to start)
        stalled = self._had_data and now - self._last_data > self.loss_timeout_s
        if not self.lost and (state in LOST_STATES or stalled):
            self._lose(state if state in LOST_STATES else "stalled")
        return False

    def _input_state(self, now: float) -> str:
        if now - self._status_at >= _STATUS_EVERY_S:
            self._status_at = now
            try:
                self._status = dict(self.source.status())
            except VibsynthError as exc:  # a status read is never allowed to stop follow
                self._status = {"state": "lost", "reason": str(exc)}
        return str(self._status.get("state", "open"))

    def _track(self, block: NDArray[np.float32]) -> None:
        with self._lock:
            for route in self._routes:
                columns = route.spec.columns
                x = block[:, columns[0]] if len(columns) == 1 else block[:, list(columns)].mean(axis=1)
                frames = route.tracker.process(x)
                if route.pan is not None:
                    self._pan(route, block[:, list(columns)])
                if not len(frames):
                    continue
                jump = False
                if route.tracker.params.transients:
                    hits = np.flatnonzero(frames.onset_strength > 0)
                    if hits.size:
                        k = int(hits[-1])
                        at = int(frames.end_sample[k])
                        curve, strength = float(frames.intensity[k]), float(frames.onset_strength[k])
                        playing = route.envelope.value(curve, at)
                        route.envelope.trigger(self._announced(route, curve, strength), strength, at, playing)
                        jump = True
                end = int(frames.end_sample[-1])
                route.level_db = (
                    max(FLOOR_DB, float(frames.level_db[-1]))
                    if frames.level_db[-1] == frames.level_db[-1]
                    else FLOOR_DB
                )
                route.gate = bool(frames.gate_open[-1])
                route.intensity = route.envelope.value(float(frames.intensity[-1]), end)
                route.balance = float(frames.balance[-1])
                self._record(route, frames.end_sample, frames.level_db, frames.intensity, frames.balance)
                if route.on:
                    self._submit(route, jump)

    def _announced(self, route: _Route, curve: float, strength: float) -> float:
        """The intensity an onset announces: the level path lags the onset path by a few ms, so at
        the onset's frame the curve still shows the level before it; the onset's rise (its raw
        strength x FULL_STRENGTH_DB, over the knob's dB range) is added to it."""
        raw = strength / max(curve, ONSET_SCALE_FLOOR)
        params = route.tracker.params
        span = params.range_db if params.mode == "audio" else self.knobs.range_db
        return min(1.0, curve + raw * FULL_STRENGTH_DB / span)

    def _record(self, route: _Route, ends: Any, levels: Any, intensity: Any, balance: Any) -> None:
        """Add a trace point per HISTORY_STEP_S of input (the newest HISTORY_POINTS are kept)."""
        fs = self.source.fs
        step = max(1, int(HISTORY_STEP_S * fs))
        for i in range(len(ends)):
            end = int(ends[i])
            if end < route.next_point:
                continue
            route.next_point = (end // step + 1) * step
            level = float(levels[i])
            route.history.append(
                (
                    end / fs,
                    level if math.isfinite(level) else FLOOR_DB,
                    float(intensity[i]),
                    float(balance[i]),
                    route.gate,
                )
            )

    def _submit(self, route: _Route, jump: bool) -> None:
        intensity, balance = route.intensity, route.balance
        sent = route.sent
        if not jump and sent is not None:
            if abs(intensity - sent[0]) < _EPS_INTENSITY and abs(balance - sent[1]) < _EPS_BALANCE:
                return
        glide = 0.0 if jump else route.tracker.hop / route.tracker.fs
        glide = min(glide, self.controller.limits.glide_max_s)
        if route.spec.kind == "channel":
            self.controller.drive(
                LAYER, channels=(route.spec.index,), intensity=intensity, balance=balance, glide_s=glide, source=SOURCE
            )
        else:
            self._drive_source(route.spec.index, intensity, balance)
        route.sent = (intensity, balance)
        self.submitted += 1

    def _pan(self, route: _Route, stereo: NDArray[np.float32]) -> None:
        """Place a panned source by its two inputs' balance (while its gate is open and the route is on)."""
        assert route.pan is not None
        u = route.pan.process(stereo)
        if not (route.on and route.gate) or (route.pan_sent is not None and abs(u - route.pan_sent) < _EPS_PAN):
            return
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            return
        index, place, first = route.spec.index, route.pan.position(u), route.pan_sent is None

        def update(table: Any, t: float) -> None:
            table.set_position(index, place, t)
            if first:
                table.set_on(index, True, t)  # a panned source appears where its input puts it

        mixer.apply(update)
        route.pan_sent = u

    def _drive_source(self, index: int, intensity: float, balance: float) -> None:
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            return  # no layout: a source route has nothing to drive (said once at start-up)
        mixer.apply(lambda table, t: table.set_texture(index, intensity=intensity, balance=balance))

    # ------------------------------------------------------------------ loss and recovery
    def _lose(self, why: str) -> None:
        self.lost = True
        self.losses += 1
        reason = self._status.get("reason") or (
            f"no frame for {self.loss_timeout_s:g} s" if why == "stalled" else "no more frames"
        )
        policy = self.follow.on_loss
        log.warning("follow: input %s (%s); %s", why, reason, "holding" if policy == "hold" else "fading out")
        if policy != "fade":
            return
        with self._lock:
            for route in self._routes:
                if not route.on:
                    continue
                route.intensity = 0.0
                route.sent = None
                if route.spec.kind == "channel":
                    glide = min(self.follow.fade_s, self.controller.limits.glide_max_s)
                    self.controller.drive(
                        LAYER, channels=(route.spec.index,), intensity=0.0, glide_s=glide, source=SOURCE
                    )
                else:
                    self._drive_source(route.spec.index, 0.0, route.balance)

    def _recover(self) -> None:
        self.lost = False
        self.recoveries += 1
        log.info("follow: input back; following again")
        with self._lock:
            for route in self._routes:
                route.tracker.reset()
                route.envelope.reset()
                route.sent = None
                if route.pan is not None:
                    route.pan.reset()

    # ------------------------------------------------------------------ live controls
    def _apply_params(self) -> None:
        if not self._pending_params:
            return
        with self._lock:
            self._pending_params = False
            for route in self._routes:
                route.tracker.set_params(route_params(self.follow, self.live, route.spec.route))

    def _set_live(self, **changes: Any) -> None:
        with self._lock:
            self.live = LiveValues(**{**self.live.__dict__, **changes})
            self._pending_params = True

    def _set_db(self, field: str, label: str, value: float) -> float:
        """Check ``value`` against the range of the setting ``follow.<field>``, then make it live."""
        low, high = bounds_of(f"follow.{field}")
        checked = check_range(f"follow {label} (dB)", value, float(low or 0.0), float(high or 0.0))
        self._set_live(**{field: checked})
        return checked

    def set_gain(self, gain_db: float) -> float:
        """Set the gain (dB, ``follow.gain_db``'s range); every route's trim is added to it."""
        return self._set_db("gain_db", "gain", gain_db)

    def set_gate(self, gate_db: float) -> float:
        """Set the gate (dB, ``follow.gate_db``'s range) of every route without its own."""
        return self._set_db("gate_db", "gate", gate_db)

    def set_focus(self, focus: str) -> str:
        """Set the focus (all, effects, bass, beat) of every route without its own (audio mode)."""
        if focus not in FOCUSES:
            raise ParameterError(f"follow focus must be one of {', '.join(FOCUSES)}, got {focus!r}")
        self._set_live(focus=focus)
        return focus

    def set_range(self, range_db: float) -> float:
        """Set the audio mode's loudness range (dB, ``follow.range_db``'s range) of every route without its own."""
        return self._set_db("range_db", "range", range_db)

    @property
    def gain_db(self) -> float:
        return self.live.gain_db

    @property
    def range_db(self) -> float:
        return self.live.range_db

    @property
    def gate_db(self) -> float:
        """The gate in force (the mode's default while ``follow.gate_db`` is null)."""
        gate = self.live.gate_db
        return default_gate_db(self.follow.mode) if gate is None else gate

    @property
    def focus(self) -> str:
        return self.live.focus

    def channels(self) -> tuple[int, ...]:
        """The 0-based output channels a route follows into."""
        with self._lock:
            return tuple(r.spec.index for r in self._routes if r.spec.kind == "channel")

    def is_on(self, channel: int) -> bool:
        """Whether follow drives 0-based ``channel`` (False for a channel no route follows into)."""
        with self._lock:
            return any(r.on for r in self._routes if r.spec.kind == "channel" and r.spec.index == channel)

    def set_channel(self, channel: int, on: bool) -> None:
        """Follow on (1) or off (0) on a 0-based output channel; off hands it back to the knobs.

        Raises
        ------
        ParameterError
            No route follows into that channel.
        """
        with self._lock:
            routes = [r for r in self._routes if r.spec.kind == "channel" and r.spec.index == channel]
            if not routes:
                followed = ", ".join(str(c + 1) for c in self.channels()) or "none"
                raise ParameterError(f"channel {channel + 1} has no follow route (followed channels: {followed})")
            for route in routes:
                if route.on == on:
                    continue
                route.on = on
                route.sent = None
                if on and not self.lost:
                    self._submit(route, False)
            if not on:
                self.controller.release(LAYER, channels=(channel,), source=SOURCE)

    def _on_panic(self) -> None:
        """Panic silences everything: follow goes off on every route (turn it on again per channel)."""
        with self._lock:
            for route in self._routes:
                route.on = False
                route.sent = None

    # ------------------------------------------------------------------ views
    def routes(self) -> list[RouteView]:
        """What each route does now."""
        with self._lock:
            return [
                RouteView(
                    r.spec.label,
                    r.spec.kind,
                    r.spec.index,
                    r.on,
                    r.level_db,
                    r.gate,
                    r.intensity,
                    r.balance,
                    r.tracker.params.mode,
                    r.tracker.params.focus,
                    None if r.pan is None else round(r.pan.fraction, 4),
                )
                for r in self._routes
            ]

    def input_status(self) -> dict[str, Any]:
        """The input's own status (device, state, reason, levels, counters)."""
        self._input_state(self.clock())
        return dict(self._status)

    def device_text(self) -> str:
        """``system (open)`` or ``USB mic: lost: device unplugged``: the input and its state."""
        status = self.input_status()
        device = str(status.get("device", "")) or "default input"
        state = "lost" if self.lost and status.get("state") in (None, "open") else str(status.get("state", "open"))
        reason = str(status.get("reason") or "")
        return f"{device} ({state}{': ' + reason if reason and state != 'open' else ''})"

    def level_db(self) -> float:
        """The loudest route's tracked input level (the gate's units: band dB or LUFS-like)."""
        views = self.routes()
        return max((v.level_db for v in views), default=FLOOR_DB)

    def gate_open(self) -> bool:
        """Whether any route's gate is open."""
        return any(v.gate for v in self.routes())

    def history(self, label: str | None = None) -> dict[str, list[tuple[float, float, float, float, bool]]]:
        """The trace: per route label, ``(input time s, level dB, intensity, balance, gate)`` points."""
        with self._lock:
            return {r.spec.label: list(r.history) for r in self._routes if label in (None, r.spec.label)}

    def snapshot(self) -> dict[str, Any]:
        """Everything a panel shows, as plain data (JSON-ready; the studio polls it)."""
        status = self.input_status()
        return {
            "device": str(status.get("device", "")),
            "state": "lost" if self.lost and status.get("state") == "open" else str(status.get("state", "open")),
            "reason": str(status.get("reason") or ""),
            "peak_db": float(status.get("level_db", FLOOR_DB)),
            "level_db": self.level_db(),
            "gate": self.gate_open(),
            "mode": self.follow.mode,
            "gain_db": self.gain_db,
            "gate_db": self.gate_db,
            "focus": self.focus,
            "range_db": self.range_db,
            "lost": self.lost,
            "stale_frames": self.stale_frames,
            "overflows": int(status.get("overflows", 0)),
            "routes": [v.__dict__ for v in self.routes()],
        }
