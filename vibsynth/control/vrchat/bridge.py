"""The VRChat bridge: avatar parameters (``/avatar/parameters/NAME``) drive sources, channels, presets, clips.

It is a namespace of the OSC handler (:meth:`~vibsynth.control.osc.handler.OscHandler.register_namespace`)
under ``/avatar/``: VRChat sends every avatar parameter to every listener, so a datagram for a
parameter no entry of ``vrchat.parameters`` maps is counted (``vrchat.unmapped``) and dropped
before it is decoded (a prefix test, a slice and one dict lookup) and gets no error reply. A
mapped one is decoded and applied (:mod:`~vibsynth.control.vrchat.drives` for the two drives):

* ``source`` at a point: on above the threshold, intensity = the texture's x the drive's amount;
* ``source`` moving: the value 0..1 places it on the path; on above the threshold; intensity the
  texture's (level) or the texture's x the velocity amount;
* ``channel``: the channel's intensity knob (and, for velocity, its balance);
* ``clip``: a rising edge across the threshold plays it (on ``channel`` or every channel);
* ``preset`` alone: a rising edge loads it on every channel.

``/avatar/change`` (a new avatar) resets everything: sources off, driven channels silent, the
bridge's clips stopped, every value back to 0. Velocity drives fade on the bridge's own thread,
every ``tick_s`` while one sounds (and not at all otherwise).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from vibsynth.control import spatial
from vibsynth.control.clips import player_of
from vibsynth.control.controller import Controller
from vibsynth.control.osc.codec import Message
from vibsynth.control.osc.monitor import describe_message, describe_sender
from vibsynth.control.oscquery.tree import NodeSpec
from vibsynth.control.spatial.sources import Position, SourceTable
from vibsynth.control.vrchat.drives import Velocity, crossed, level_amount
from vibsynth.errors import VibsynthError
from vibsynth.settings.models_vrchat import AvatarParameter, Vrchat, target_of

__all__ = ["ROOT", "PARAMETERS", "CHANGE", "SOURCE", "Mapped", "VrchatStats", "VrchatBridge"]

log = logging.getLogger(__name__)

ROOT = "/avatar/"
PARAMETERS = "/avatar/parameters/"
CHANGE = "/avatar/change"
#: ``source`` of the bridge's knob moves (shown to /notify subscribers and monitors).
SOURCE = "vrchat"
_PARAMETERS_RAW = PARAMETERS.encode()
_NAME_START = len(_PARAMETERS_RAW)
_NUMBER_TAGS = frozenset("ifdh")
#: Longest avatar id kept for status.
_AVATAR_ID_MAX = 128


@dataclass
class Mapped:
    """One mapped parameter's state (under the bridge's lock)."""

    spec: AvatarParameter
    kind: str  # source, channel, clip or preset
    path: str
    base: tuple[float, float] = (1.0, 0.0)  # the texture's (intensity, balance)
    value: float = 0.0
    velocity: Velocity | None = None
    sounding: bool = False  # the last amount applied was > 0 (a velocity drive still to fade)
    heard: bool = False  # a value arrived since the start or the last reset


@dataclass
class VrchatStats:
    """Counters of the bridge (``vrchat.*`` in ``/status.reply``)."""

    mapped: int = 0  # messages of mapped parameters applied
    unmapped: int = 0  # parameters (and /avatar/ addresses) nothing maps: dropped, no reply
    bad_values: int = 0  # a mapped parameter with no single number/bool argument
    errors: int = 0  # refused downstream (unknown clip or preset, no layout...)
    avatar_changes: int = 0
    avatar: str = ""
    primed: int = 0  # mapped parameters whose value was read from VRChat's OSCQuery tree


@dataclass
class _Tick:
    thread: threading.Thread | None = None
    stop: bool = False
    cond: threading.Condition = field(default_factory=threading.Condition)


class VrchatBridge:
    """Avatar parameters -> sources, channels, presets and clips (an OSC namespace table).

    Parameters
    ----------
    settings : Vrchat
        The typed ``vrchat:`` section.
    controller : Controller
        Channels and presets through it; the sources' mixer and the clip player are found from it.
    clock : callable
        Monotonic seconds (injectable for tests).
    tick_s : float
        Period of the velocity fades' updates.
    """

    name = "vrchat"

    def __init__(
        self,
        settings: Vrchat,
        controller: Controller,
        *,
        clock: Callable[[], float] = time.monotonic,
        tick_s: float = 0.01,
    ) -> None:
        self.settings = settings
        self.controller = controller
        self.clock = clock
        self.tick_s = float(tick_s)
        self.stats = VrchatStats()
        self.on_value: Callable[[str], None] = lambda path: None  # OSCQuery listeners (the adapter sets it)
        self.found: str = ""  # VRChat's OSC input address (HOST_INFO, or the fallback), for status
        self.on_avatar_change: Callable[[], None] = lambda: None  # the service reads VRChat's values again
        self._lock = threading.RLock()
        self._tick = _Tick()
        self._by_name: dict[bytes, Mapped] = {}
        for spec in settings.parameters:
            kind = target_of(spec)
            velocity = Velocity(settings.velocity_full, settings.velocity_fade_ms / 1000.0)
            self._by_name[spec.name.encode()] = Mapped(
                spec, kind, PARAMETERS + spec.name, velocity=velocity if spec.drive == "velocity" else None
            )

    # ------------------------------------------------------------------ the handler's side
    def take_packet(self, data: bytes) -> bool:
        """Drop (and count) a datagram for an unmapped parameter before it is decoded."""
        if not data.startswith(_PARAMETERS_RAW):
            return False  # /avatar/change and the rest: decoded, then handle()
        end = data.find(b"\x00", _NAME_START)
        if end < 0 or data[_NAME_START:end] in self._by_name:
            return False
        self.stats.unmapped += 1
        return True

    def handle(self, msg: Message, peer: Any, at_frame: int | None) -> None:
        """One decoded message under ``/avatar/`` (no error reply: VRChat reads none)."""
        address = msg.address
        if address == CHANGE:
            self._avatar_changed(msg)
            return
        mapped = self._by_name.get(address[len(PARAMETERS) :].encode()) if address.startswith(PARAMETERS) else None
        if mapped is None:
            self.stats.unmapped += 1
            return
        value = _value_of(msg)
        if value is None:
            self.stats.bad_values += 1
            self.controller.count_error("vrchat.bad_value")
            log.debug("VRChat: %s: expected one float, int or bool, got %r", address, msg.types)
            return
        tap = self.controller.tap
        if tap.active:
            tap.publish(SOURCE, partial(describe_message, msg, _sender(peer), at_frame))
        self.stats.mapped += 1
        self.apply(mapped.spec.name, value)

    def status_pairs(self) -> list[tuple[str, object]]:
        """``vrchat.*`` pairs of ``/status.reply``."""
        s = self.stats
        return [
            ("vrchat.mapped", s.mapped),
            ("vrchat.unmapped", s.unmapped),
            ("vrchat.bad_values", s.bad_values),
            ("vrchat.errors", s.errors),
            ("vrchat.avatar_changes", s.avatar_changes),
            ("vrchat.avatar", s.avatar),
            ("vrchat.primed", s.primed),
            ("vrchat.osc", self.found),
        ]

    # ------------------------------------------------------------------ OSCQuery
    def nodes(self) -> dict[str, NodeSpec]:
        """``/avatar/change`` and each mapped parameter as OSCQuery nodes (VRChat sends avatar data
        to services whose tree has ``/avatar``)."""
        out = {CHANGE: NodeSpec("s", "VRChat: a new avatar (its id): resets every mapped parameter")}
        for m in self._by_name.values():
            what = {"source": f"source {m.spec.source}", "channel": f"channel {m.spec.channel}"}.get(m.kind, m.kind)
            out[m.path] = NodeSpec(
                "f",
                f"VRChat avatar parameter -> {what} ({m.spec.drive})",
                value=partial(self._node_value, m),
                range=lambda ctx: [{"MIN": -1.0, "MAX": 1.0}],
            )
        return out

    def _node_value(self, mapped: Mapped, ctx: Any) -> list[float]:
        return [mapped.value]

    # ------------------------------------------------------------------ applying
    def value(self, name: str) -> float:
        """A mapped parameter's last value (0 until one arrives)."""
        return self._by_name[name.encode()].value

    def apply(self, name: str, value: float) -> None:
        """A new value of mapped parameter ``name`` (the tests' entry point too)."""
        mapped = self._by_name[name.encode()]
        now = self.clock()
        with self._lock:
            previous, mapped.value = mapped.value, value
            mapped.heard = True
            kind, spec = mapped.kind, mapped.spec
            try:
                if kind in ("clip", "preset"):
                    if crossed(previous, value, spec.threshold):
                        self._fire(mapped)
                else:
                    if mapped.velocity is not None:
                        mapped.velocity.change(value, now)
                    self._drive(mapped, now)
            except VibsynthError as exc:
                self._refused(spec.name, exc)
        if mapped.velocity is not None and mapped.sounding:
            with self._tick.cond:
                self._tick.cond.notify()
        self.on_value(mapped.path)

    def prime(self, values: Mapping[str, float], avatar: str = "") -> int:
        """Start from VRChat's current values (its OSCQuery tree, read once it is found).

        A mapped parameter no message has reached yet takes its value as if it had arrived, with
        two differences: a value already above a clip's or preset's threshold is the state, not
        a rising edge (nothing plays), and a velocity drive starts still (a resting value is no
        stroke). A parameter a message already set keeps it (the message is newer than the read).

        Parameters
        ----------
        values : mapping of str to float
            Parameter name -> value (a bool as 1/0), :func:`vibsynth.control.vrchat.values.read_avatar`.
        avatar : str
            The avatar's id, for status (kept when empty).

        Returns
        -------
        primed : int
            Mapped parameters set.
        """
        primed = 0
        with self._lock:
            if avatar and not self.stats.avatar:
                self.stats.avatar = avatar[:_AVATAR_ID_MAX]
            for name, value in values.items():
                mapped = self._by_name.get(name.encode())
                if mapped is None or mapped.heard:
                    continue
                primed += 1
                if mapped.kind in ("clip", "preset"):
                    mapped.value = value
                    mapped.heard = True
                    self.on_value(mapped.path)
                    continue
                if mapped.velocity is not None:
                    mapped.velocity.reset()
                self.apply(mapped.spec.name, value)
            self.stats.primed += primed
        return primed

    def _refused(self, name: str, exc: VibsynthError) -> None:
        self.stats.errors += 1
        self.controller.count_error("vrchat.refused")
        log.debug("VRChat: %s: %s", name, exc)

    def _fire(self, mapped: Mapped) -> None:
        spec = mapped.spec
        if mapped.kind == "preset":
            assert spec.preset is not None
            self.controller.load_preset(spec.preset, source=SOURCE)
            return
        player = player_of(self.controller)
        if player is None:
            raise VibsynthError("clips are not available (no clip player is running)")
        assert spec.clip is not None
        player.play(spec.clip, channels=None if spec.channel is None else (spec.channel - 1,), source=SOURCE)

    def _amount(self, mapped: Mapped, now: float) -> float:
        if mapped.velocity is not None:
            return mapped.velocity.amount(now)
        if mapped.spec.moving is not None:
            return 1.0  # a moving touch plays its texture; the value is where it is
        return level_amount(mapped.value)

    def _texture(self, mapped: Mapped, amount: float) -> tuple[float, float]:
        intensity, balance = mapped.base
        if mapped.velocity is not None:
            limits = self.controller.limits
            balance += self.settings.velocity_brightness * mapped.velocity.peak
            balance = min(max(balance, limits.balance_min), limits.balance_max)
        return min(max(intensity * amount, 0.0), 1.0), balance

    def _drive(self, mapped: Mapped, now: float) -> None:
        """Send a source's or channel's state for the parameter's value (and velocity) at ``now``."""
        amount = self._amount(mapped, now)
        mapped.sounding = amount > 0.0
        intensity, balance = self._texture(mapped, amount)
        spec = mapped.spec
        if mapped.kind == "channel":
            assert spec.channel is not None
            chans = (spec.channel - 1,)
            glide = self.tick_s if mapped.velocity is not None else None
            if mapped.velocity is not None:
                self.controller.set_knob("balance", balance, channels=chans, glide_s=glide, source=SOURCE)
            self.controller.set_knob("intensity", intensity, channels=chans, glide_s=glide, source=SOURCE)
            return
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            raise VibsynthError("sources need a layout (layout: in the config; docs/vr.md)")
        assert spec.source is not None
        index = spec.source - 1
        on = mapped.value > spec.threshold and amount > 0.0
        position = self._position(mapped)

        def update(table: SourceTable, t: float) -> None:
            if table.view(index, t).target != position:
                table.set_position(index, position, t)
            table.set_texture(index, intensity, balance)
            table.set_on(index, on, t)

        mixer.apply(update)

    @staticmethod
    def _position(mapped: Mapped) -> Position:
        spec = mapped.spec
        if spec.moving is None:
            assert spec.at is not None
            return SourceTable.check_position(tuple(spec.at))
        (a, b), f = spec.moving, level_amount(mapped.value)
        a3, b3 = SourceTable.check_position(tuple(a)), SourceTable.check_position(tuple(b))
        return (a3[0] + f * (b3[0] - a3[0]), a3[1] + f * (b3[1] - a3[1]), a3[2] + f * (b3[2] - a3[2]))

    # ------------------------------------------------------------------ reset
    def _avatar_changed(self, msg: Message) -> None:
        self.stats.avatar_changes += 1
        if len(msg.args) == 1 and msg.types in ("s", "S"):
            self.stats.avatar = str(msg.args[0])[:_AVATAR_ID_MAX]
        self.reset()
        self.on_avatar_change()

    def reset(self) -> None:
        """Every mapped parameter back to 0: sources off, driven channels silent, the bridge's clips stopped."""
        with self._lock:
            for mapped in self._by_name.values():
                mapped.value = 0.0
                mapped.heard = False
                if mapped.velocity is not None:
                    mapped.velocity.reset()
                try:
                    if mapped.kind in ("source", "channel"):
                        self._drive(mapped, self.clock())
                    elif mapped.kind == "clip" and player_of(self.controller) is not None:
                        spec = mapped.spec
                        chans = None if spec.channel is None else (spec.channel - 1,)
                        player_of(self.controller).stop(channels=chans, source=SOURCE)  # type: ignore[union-attr]
                except VibsynthError as exc:
                    self._refused(mapped.spec.name, exc)
                self.on_value(mapped.path)

    # ------------------------------------------------------------------ lifetime
    def start(self) -> None:
        """Read the mapped presets' textures, silence the driven targets, start the fades' thread."""
        resolver = self.controller.preset_resolver
        for mapped in self._by_name.values():
            preset = mapped.spec.preset
            if preset is not None and mapped.kind in ("source", "channel"):
                try:
                    if resolver is None:
                        raise VibsynthError("no preset library is loaded")
                    found = resolver(preset)
                    mapped.base = (float(found.intensity), float(found.balance))
                except VibsynthError as exc:
                    log.warning("vrchat.parameters %s: %s (plays intensity 1, balance 0)", mapped.spec.name, exc)
        with self._lock:
            for mapped in self._by_name.values():
                if mapped.kind == "channel" and mapped.spec.channel is not None:
                    limits = self.controller.limits
                    balance = min(max(mapped.base[1], limits.balance_min), limits.balance_max)
                    self.controller.set_knob("balance", balance, channels=(mapped.spec.channel - 1,), source=SOURCE)
        if any(m.velocity is not None for m in self._by_name.values()):
            self._tick.stop = False
            self._tick.thread = threading.Thread(target=self._run, name="vibsynth-vrchat", daemon=True)
            self._tick.thread.start()

    def stop(self) -> None:
        """Stop the fades' thread (idempotent)."""
        with self._tick.cond:
            self._tick.stop = True
            self._tick.cond.notify()
        if self._tick.thread is not None:
            self._tick.thread.join(timeout=2.0)
            self._tick.thread = None

    def describe(self) -> str:
        """One line for the start-up banner."""
        return f"VRChat: {len(self._by_name)} avatar parameter(s) mapped under {ROOT}"

    def tick(self) -> bool:
        """Update every fading velocity drive once; True while one still sounds."""
        now = self.clock()
        sounding = False
        with self._lock:
            for mapped in self._by_name.values():
                if mapped.velocity is None or not mapped.sounding:
                    continue
                try:
                    self._drive(mapped, now)
                except VibsynthError as exc:
                    mapped.sounding = False
                    self._refused(mapped.spec.name, exc)
                sounding = sounding or mapped.sounding
        return sounding

    def _run(self) -> None:
        cond = self._tick.cond
        while True:
            with cond:
                if self._tick.stop:
                    return
                if not self._any_sounding():
                    cond.wait()
                    continue
            try:
                self.tick()
            except Exception:  # never let the thread die: log, go on
                log.exception("VRChat: the velocity fades failed")
            with cond:
                if self._tick.stop:
                    return
                cond.wait(self.tick_s)

    def _any_sounding(self) -> bool:
        return any(m.velocity is not None and m.sounding for m in self._by_name.values())


def _value_of(msg: Message) -> float | None:
    """The one argument as a number: a float or int as is, a bool 1/0; None for anything else."""
    if len(msg.args) != 1:
        return None
    tag = msg.types[:1]
    if tag in ("T", "F"):
        return 1.0 if tag == "T" else 0.0
    if tag in _NUMBER_TAGS:
        number = float(msg.args[0])
        return number if math.isfinite(number) else None
    return None


def _sender(peer: Any) -> str:
    return describe_sender(getattr(peer, "address", None), getattr(peer, "datagram", True))
