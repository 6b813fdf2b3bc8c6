"""OSC control server: the address space VR apps and live-coding tools drive (see docs/osc.md).

Layers (each its own module, tests use each without a socket):

* :mod:`~vibsynth.control.osc.codec` - wire format (strict, bounded decoder);
* :mod:`~vibsynth.control.osc.address` - address table and OSC 1.0 pattern matching;
* :class:`OscHandler` (here) - one method per address: validates arguments at the edge,
  calls the :class:`~vibsynth.control.controller.Controller`, replies to the sender;
  bundles with future timetags are converted to stream frames (``at_frame``);
* :mod:`~vibsynth.control.osc.transport` - UDP (and optional TCP/SLIP) transports;
* :mod:`~vibsynth.control.osc.workers` - ``/notify`` pushes and deferred ``/sync`` replies.

The service calls :func:`add_arguments` and :func:`create` (adapter contract of
:mod:`vibsynth.control`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Protocol

from vibsynth.control.clips.status import clip_status
from vibsynth.control.controller import Controller, KnobEvent, check_range
from vibsynth.control.midi import learn_hook as _midi_learn_hook
from vibsynth.control.osc.address import AddressSpace
from vibsynth.control.osc.clock import StreamClock
from vibsynth.control.osc.codec import (
    IMMEDIATE,
    MalformedPacket,
    Message,
    decode_packet,
    encode_message,
    iter_messages,
    ntp_to_unix,
)
from vibsynth.control.osc.methods import Getter, Method, MethodTable, OscArgumentError
from vibsynth.control.osc.methods import arg_count as _arg_count
from vibsynth.control.osc.methods import flag as _flag
from vibsynth.control.osc.methods import number as _number
from vibsynth.control.osc.methods import string as _string
from vibsynth.control.osc.monitor import MonitorWorker, describe_message, describe_sender
from vibsynth.control.osc.replies import (
    REPLY_AMPLIFICATION,
    ReplyBudget,
    _osc_string_size,
    fit_osc_string,
    is_loopback,
    redact_paths,
)
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.osc.workers import Notifier, PeerLike, SyncWorker, setter_message
from vibsynth.control.status import channel_status, engine_status, follow_status, output_status
from vibsynth.control.tap import InputTap
from vibsynth.errors import ClipError, ParameterError, PresetError, ScheduleFullError, VibsynthError

log = logging.getLogger(__name__)

SOURCE = "osc"
SPEED_SOURCE = "osc-speed"
_COALESCED = frozenset({"intensity", "balance", "texture", "speed"})
#: The settings ``get`` answers itself (registered tables add theirs, e.g. ``clip``).
_GET_FIELDS = ("intensity", "balance", "glide", "mute", "preset", "texture", "driver")


@dataclass
class OscStats:
    """Counters of the OSC handler (written on the receive thread only)."""

    messages: int = 0
    bundles: int = 0
    scheduled: int = 0
    malformed: int = 0
    errors: int = 0
    error_replies_suppressed: int = 0
    replies_truncated: int = 0  # error replies cut to the UDP reply budget
    replies_dropped: int = 0  # replies not sent: over the UDP reply budget


class NamespaceTable(Protocol):
    """Every address under a root outside the prefix (VRChat's ``/avatar/``): :meth:`OscHandler.register_namespace`."""

    def take_packet(self, data: bytes) -> bool:
        """A datagram under the root, before it is decoded: True when it is done with (e.g. counted and
        dropped); False to have it decoded and handed to :meth:`handle` (the table counts its own problems)."""
        ...

    def handle(self, msg: Message, peer: PeerLike, at_frame: int | None) -> None:
        """One decoded message under the root (no error reply: the table counts what it refuses)."""
        ...

    def status_pairs(self) -> list[tuple[str, object]]:
        """The table's ``/status.reply`` pairs."""
        ...


class _TokenBucket:
    """At most ``rate`` events per second (burst ``rate``); used to cap error replies."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.tokens = rate
        self.last = time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.rate, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class OscHandler:
    """Decodes packets, routes messages to methods, replies; no sockets, no threads of its own.

    Parameters
    ----------
    controller : Controller
        Everything goes through it (validation, state, engine commands).
    prefix : str
        Address prefix (default ``/vibsynth``).
    speed_curve : SpeedCurve
    schedule_horizon_s : float
        Bundles timetagged further ahead are rejected with an error reply.
    notifier : Notifier, optional
        Serves ``/notify`` (None: error reply).
    sync_worker : SyncWorker, optional
        Serves ``/sync`` requests that cannot be answered at once (None: answer with a
        short blocking wait; for tests).
    block_size : int, optional
        Reported by ``/status`` when the engine does not expose one.
    error_reply_rate : float
        Error replies per second (beyond: counted, not sent), so a flood of bad
        packets costs no reply traffic.
    extra_status : callable, optional
        Returns extra ``(key, value)`` pairs for ``/status`` (transport counters).
    tap : InputTap, optional
        Where received messages and answered errors are published (monitors, status).
    monitor : MonitorWorker, optional
        Serves ``/monitor`` (None: error reply).
    """

    def __init__(
        self,
        controller: Controller,
        *,
        prefix: str = "/vibsynth",
        speed_curve: SpeedCurve | None = None,
        schedule_horizon_s: float = 10.0,
        notifier: Notifier | None = None,
        sync_worker: SyncWorker | None = None,
        block_size: int | None = None,
        error_reply_rate: float = 500.0,
        extra_status: Callable[[], list[tuple[str, object]]] | None = None,
        tap: InputTap | None = None,
        monitor: MonitorWorker | None = None,
    ) -> None:
        self.controller = controller
        self.engine = controller.engine
        self.space = AddressSpace(prefix, controller.channels)
        self.prefix = self.space.prefix
        self.speed_curve = speed_curve or SpeedCurve([[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]])
        self.horizon_s = float(schedule_horizon_s)
        self.notifier = notifier
        self.sync_worker = sync_worker
        self.block_size = block_size
        self.extra_status = extra_status
        self.tap = tap if tap is not None else InputTap()
        self.monitor = monitor
        self.clock = StreamClock(self.engine)
        self.stats = OscStats()
        self._error_bucket = _TokenBucket(error_reply_rate)
        self._error_address = f"{self.prefix}/error"
        self._methods: dict[str, Method] = {
            "intensity": self._on_intensity,
            "balance": self._on_balance,
            "texture": self._on_texture,
            "glide": self._on_glide,
            "mute": self._on_mute,
            "panic": self._on_panic,
            "preset": self._on_preset,
            "speed": self._on_speed,
            "get": self._on_get,
            "status": self._on_status,
            "ping": self._on_ping,
            "sync": self._on_sync,
            "notify": self._on_notify,
            "learn": self._on_learn,
            "monitor": self._on_monitor,
        }
        self._getters: dict[str, Getter] = {}  # get NAME answered by a registered table (see register)
        self._namespaces: tuple[tuple[str, bytes, NamespaceTable], ...] = ()  # see register_namespace
        # balance set by anything but /speed: the base that the speed shift is added to
        self._base_balance = [s.balance for s in controller.state()]
        # coalescing of immediate knob moves within one receive batch (see handle_batch)
        self._batching = False
        self._pending: dict[tuple, Callable[[], object]] = {}
        self._base_lock = threading.Lock()
        self._unsubscribe: Callable[[], None] | None = None
        if self.speed_curve.balance_per_decade != 0.0:
            self._unsubscribe = controller.subscribe(self._track_balance)

    def register(self, table: MethodTable) -> None:
        """Take on a table's methods and ``get`` names (the sources', the clips': control/osc/tables.py).

        A route whose method no table registered is answered with an error (not available).

        Raises
        ------
        ParameterError
            A name the handler already has (each method has one definition).
        """
        methods, getters = dict(table.methods()), dict(table.getters())
        taken = (methods.keys() & self._methods.keys()) | (getters.keys() & {*self._getters, *_GET_FIELDS})
        if taken:
            raise ParameterError(f"OSC methods registered twice: {', '.join(sorted(taken))}")
        self._methods.update(methods)
        self._getters.update(getters)

    def register_namespace(self, root: str, table: NamespaceTable) -> None:
        """Hand every address under ``root`` (``/avatar/``, outside the prefix) to ``table``.

        A datagram under it goes to ``table.take_packet`` before it is decoded, so a flood the table
        does not want (VRChat's unmapped avatar parameters) costs a prefix test and what the table
        does; otherwise it is decoded and each message goes to ``table.handle``, with no error reply.

        Raises
        ------
        ParameterError
            A root that is not ``/.../`` or lies under the prefix or another root.
        """
        if not (root.startswith("/") and root.endswith("/") and len(root) > 2):
            raise ParameterError(f"namespace root {root!r} must look like /name/")
        taken = [r for r, _, _ in self._namespaces] + ([self.prefix + "/"] if self.prefix else [])
        if not self.prefix or any(root.startswith(r) or r.startswith(root) for r in taken):
            raise ParameterError(f"namespace root {root!r} overlaps the OSC address space")
        self._namespaces += ((root, root.encode(), table),)

    def method_names(self) -> frozenset[str]:
        """The methods this handler answers (its own and the registered tables'): what discovery lists."""
        return frozenset(self._methods)

    def get_names(self) -> tuple[str, ...]:
        """The names ``get`` answers (its own and the registered tables')."""
        return (*_GET_FIELDS, *self._getters)

    def close(self) -> None:
        """Detach from the controller."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

    # -------------------------------------------------------------- entry points
    def handle_packet(self, data: bytes, peer: PeerLike) -> None:
        """Handle one datagram (or SLIP frame): decode, schedule, dispatch; never raises for bad input.

        Replies to a UDP peer on another host total at most :data:`REPLY_AMPLIFICATION` x
        ``len(data)`` bytes (see :class:`ReplyBudget`).
        """
        for _, raw, table in self._namespaces:
            if data.startswith(raw) and table.take_packet(data):
                return
        peer = self._limit_replies(peer, len(data))
        try:
            packet = decode_packet(data)
        except MalformedPacket as exc:
            self.stats.malformed += 1
            self.controller.count_error("osc.malformed")
            log.debug("OSC: malformed packet of %d bytes: %s", len(data), exc)
            return
        if isinstance(packet, Message):
            self.handle_message(packet, peer)
            return
        self.stats.bundles += 1
        frames: dict[int, int | None | str] = {}
        for message, timetag in iter_messages(packet):
            at = frames.get(timetag)
            if timetag not in frames:
                at = frames[timetag] = self._frame_for(timetag)
            if isinstance(at, str):
                self.stats.messages += 1
                self._error(peer, message.address, at, "osc.horizon")
                continue
            self.handle_message(message, peer, at)

    def handle_batch(self, items: Iterable[tuple[bytes, PeerLike]]) -> None:
        """Handle packets that were queued together in the socket, coalescing immediate knob moves.

        Every message is validated (and errors replied) as it comes, but immediate
        ``intensity``/``balance``/``texture``/``speed`` moves are held until the end of the
        batch (or until any other method needs the state) and only the last move per
        address and channel set reaches the engine. The result is exactly the state of
        sequential application; a server that fell behind catches up without flooding
        the audio thread with commands it would apply in the same block anyway.
        """
        self._batching = True
        try:
            self.clock.sample()  # keep the wall-clock/stream estimate fresh with every batch
            for data, peer in items:
                self.handle_packet(data, peer)
        finally:
            self._batching = False
            self.flush()

    def flush(self) -> None:
        """Submit the knob moves held back by :meth:`handle_batch`, in last-arrival order."""
        pending, self._pending = self._pending, {}
        for submit in pending.values():
            try:
                submit()
            except VibsynthError as exc:  # already validated; only a race could get here
                self.controller.count_error("osc.invalid_value")
                log.debug("OSC: deferred knob move failed: %s", exc)

    def _defer(self, key: tuple, submit: Callable[[], object]) -> None:
        self._pending.pop(key, None)
        self._pending[key] = submit

    def handle_message(self, msg: Message, peer: PeerLike, at_frame: int | None = None) -> None:
        """Route one decoded message (to every method its address pattern matches)."""
        self.stats.messages += 1
        for root, _, table in self._namespaces:
            if msg.address.startswith(root):
                if self._pending:
                    self.flush()
                table.handle(msg, peer, at_frame)
                return
        if isinstance(peer, ReplyBudget):
            peer.request = msg.address
        if self.tap.active:
            self.tap.publish("osc", partial(describe_message, msg, _sender(peer), at_frame))
        try:
            routes = self.space.match(msg.address)
        except ParameterError as exc:
            self._error(peer, msg.address, str(exc), "osc.bad_pattern")
            return
        if not routes:
            self._error(peer, msg.address, self.space.why_unknown(msg.address), "osc.unknown_address")
            return
        if len(routes) == 1:
            route = routes[0]
            calls: list[tuple[str, tuple[int, ...] | None]] = [
                (route.method, None if route.channel is None else (route.channel,))
            ]
        else:
            calls = self.space.group(routes)
        for method, channels in calls:
            if self._pending and (at_frame is not None or method not in _COALESCED):
                self.flush()  # keep order with everything that is not coalesced
            call = self._methods.get(method)
            if call is None:
                self._error(peer, msg.address, f"{method}: not available on this server", "osc.unavailable")
                continue
            try:
                call(msg, channels, peer, at_frame)
            except OscArgumentError as exc:
                self._error(peer, msg.address, f"{method}: {exc}", "osc.bad_arguments")
            except PresetError as exc:
                self._error(peer, msg.address, str(exc), "osc.preset")
            except ScheduleFullError as exc:
                self._error(peer, msg.address, str(exc), "osc.schedule_full")
            except ClipError as exc:  # unknown clip (with "did you mean"), or a broken clip file
                self._error(peer, msg.address, str(exc), "osc.clip")
            except ParameterError as exc:
                self._error(peer, msg.address, str(exc), "osc.invalid_value")
            except VibsynthError as exc:
                self._error(peer, msg.address, str(exc), "osc.error")

    # -------------------------------------------------------------- helpers
    def _frame_for(self, timetag: int) -> int | None | str:
        """at_frame for a timetag (None = now) or an error message when beyond the horizon."""
        if timetag == IMMEDIATE:
            return None
        when = ntp_to_unix(timetag)
        ahead = when - time.time()
        if ahead <= 0.0:
            return None
        if ahead > self.horizon_s:
            return (
                f"timetag is {ahead:.3g} s ahead, beyond the schedule horizon of {self.horizon_s:g} s "
                "(osc.schedule_horizon_s); message rejected"
            )
        frame, current = self.clock.frame_at(when)
        if frame <= current:
            return None
        self.stats.scheduled += 1
        return frame

    def _error(self, peer: PeerLike, address: str, message: str, kind: str) -> None:
        self.stats.errors += 1
        self.controller.count_error(kind)
        log.debug("OSC error %s: %s: %s", kind, address, message)
        if not self._error_bucket.take():
            self.stats.error_replies_suppressed += 1
            return
        self.tap.error(f"{address}: {message} ({kind}, from {_sender(peer)})")
        room = peer.room if isinstance(peer, ReplyBudget) else None
        data = self._error_packet(address, redact_paths(message, self.prefix), room)
        if data is None:
            self.stats.replies_dropped += 1
        else:
            peer.send(data)

    def _error_packet(self, address: str, message: str, room: int | None) -> bytes | None:
        """``/error address message`` in at most ``room`` bytes (None = any size): cut to fit, None if impossible."""
        data = encode_message(self._error_address, (address, message), "ss")
        if room is None or len(data) <= room:
            return data
        strings = room - (len(encode_message(self._error_address, ("", ""), "ss")) - 8)  # room for both strings
        if strings < 8:
            return None
        self.stats.replies_truncated += 1
        address = fit_osc_string(address, min(_osc_string_size(address), strings - 4))
        message = fit_osc_string(message, strings - _osc_string_size(address))
        return encode_message(self._error_address, (address, message), "ss")

    def _limit_replies(self, peer: PeerLike, request_size: int) -> PeerLike:
        """``peer`` itself, or a :class:`ReplyBudget` for a UDP peer on another host."""
        if not getattr(peer, "datagram", False):
            return peer
        address = getattr(peer, "address", None)
        if address and is_loopback(str(address[0])):
            return peer
        return ReplyBudget(peer, REPLY_AMPLIFICATION * request_size, self._reply_refused)

    def _reply_refused(self, budget: ReplyBudget, size: int) -> None:
        """A reply did not fit in the UDP reply budget: count it; say why once per request (if that fits)."""
        self.stats.replies_dropped += 1
        if budget.refused:
            return
        budget.refused = True
        self._error(
            budget,
            budget.request,
            f"reply of {size} bytes not sent: replies to a UDP client on another "
            f"host total at most {REPLY_AMPLIFICATION}x the request ({budget.limit} bytes); use TCP "
            "(osc.tcp) or a longer request",
            "osc.reply_limit",
        )

    def _reply(self, peer: PeerLike, address: str, args: Sequence[object] = (), types: str | None = None) -> None:
        peer.send(encode_message(address, args, types))

    def _track_balance(self, event: KnobEvent) -> None:
        if event.name == "balance" and event.source != SPEED_SOURCE:
            with self._base_lock:
                self._base_balance[event.channel] = float(event.value)  # type: ignore[arg-type]

    # -------------------------------------------------------------- knob methods
    def _set_knob(self, name: str, value: float, channels, at_frame) -> None:
        if self._batching and at_frame is None:
            value = self.controller.validate_knob(name, value)
            self._defer(
                (name, channels), lambda: self.controller.set_knob(name, value, channels=channels, source=SOURCE)
            )
        else:
            self.controller.set_knob(name, value, channels=channels, at_frame=at_frame, source=SOURCE)

    def _on_intensity(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "intensity 0..1")
        self._set_knob("intensity", _number(msg, 0, "intensity"), channels, at_frame)

    def _on_balance(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "balance")
        self._set_knob("balance", _number(msg, 0, "balance"), channels, at_frame)

    def _on_texture(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (2,), "intensity, balance")
        intensity, balance = _number(msg, 0, "intensity"), _number(msg, 1, "balance")
        if self._batching and at_frame is None:
            self.controller.validate_knob("intensity", intensity)
            self.controller.validate_knob("balance", balance)
            self._defer(
                ("texture", channels),
                lambda: self.controller.set_texture(intensity, balance, channels=channels, source=SOURCE),
            )
        else:
            self.controller.set_texture(intensity, balance, channels=channels, at_frame=at_frame, source=SOURCE)

    def _on_glide(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "glide in ms")
        max_ms = self.controller.limits.glide_max_s * 1000.0
        ms = check_range("glide (ms)", _number(msg, 0, "glide"), 0.0, max_ms)
        self.controller.set_glide(ms / 1000.0, channels=channels, at_frame=at_frame, source=SOURCE)

    def _on_mute(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "0 or 1")
        self.controller.set_mute(_flag(msg, 0, "mute"), channels=channels, at_frame=at_frame, source=SOURCE)

    def _on_panic(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (0, 1), "none, or a button value")
        if msg.args and not _flag(msg, 0, "panic"):
            return  # button release (0): nothing to do
        self.controller.panic(source=SOURCE)

    def _on_preset(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "preset name")
        self.controller.load_preset(_string(msg, 0, "preset"), channels=channels, at_frame=at_frame, source=SOURCE)

    def _on_speed(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "speed in mm/s")
        speed = _number(msg, 0, "speed")
        if speed < 0.0:
            raise ParameterError(f"speed must be >= 0 mm/s, got {speed:g}")
        curve = self.speed_curve
        if curve.balance_per_decade != 0.0:
            self.flush()
            shift = curve.balance_shift(speed)
            limits = self.controller.limits
            chans = range(self.controller.channels) if channels is None else channels
            with self._base_lock:
                bases = {c: self._base_balance[c] for c in chans}
            for value in sorted(set(bases.values())):
                group = tuple(c for c, b in bases.items() if b == value)
                target = min(max(value + shift, limits.balance_min), limits.balance_max)
                self.controller.set_knob("balance", target, channels=group, at_frame=at_frame, source=SPEED_SOURCE)
            self.controller.set_knob(
                "intensity", curve.intensity(speed), channels=channels, at_frame=at_frame, source=SOURCE
            )
            return
        self._set_knob("intensity", curve.intensity(speed), channels, at_frame)

    # -------------------------------------------------------------- queries
    def _on_get(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "setting name")
        name = _string(msg, 0, "setting")
        getter = self._getters.get(name)
        if getter is not None:
            getter(peer, channels)
            return
        if name not in _GET_FIELDS:
            known = ", ".join((*_GET_FIELDS, *self._getters))
            raise ParameterError(f"unknown setting {name!r}; known: {known}")
        states = self.controller.state()
        chans = range(len(states)) if channels is None else channels

        def values(ch: int) -> tuple:
            s = states[ch]
            if name == "texture":
                return (s.intensity, s.balance)
            if name == "driver":  # which layer plays: knobs, sources or clip (read-only)
                return (self.controller.driver(ch),)
            return (
                {
                    "intensity": s.intensity,
                    "balance": s.balance,
                    "glide": s.glide_s,
                    "mute": s.muted,
                    "preset": s.preset,
                }[name],
            )

        per_channel = {ch: values(ch) for ch in chans}
        if channels is None and len(set(per_channel.values())) == 1:
            targets: list[tuple[int | None, tuple]] = [(None, per_channel[0])]
        else:
            targets = list(per_channel.items())
        for ch, vals in targets:
            if name == "texture":
                base = self.prefix if ch is None else f"{self.prefix}/ch/{ch + 1}"
                peer.send(encode_message(f"{base}/texture", vals, "ff"))
            else:
                peer.send(setter_message(self.prefix, ch, name, vals[0]))

    def status_pairs(self) -> list[tuple[str, object]]:
        """The ``/status.reply`` content as ``(key, value)`` pairs (-1 = not known); parts in control/status.py."""
        ctl = self.controller
        pairs = engine_status(ctl, self.block_size) + [
            ("messages", self.stats.messages),
            ("scheduled", self.stats.scheduled),
            ("malformed", self.stats.malformed),
            ("errors", int(sum(ctl.error_counts.values()))),
            ("subscribers", len(self.notifier) if self.notifier is not None else 0),
        ]
        pairs += output_status(ctl, self.tap, fit_osc_string)
        if self.extra_status is not None:
            pairs.extend(self.extra_status())
        pairs += [("replies_truncated", self.stats.replies_truncated), ("replies_dropped", self.stats.replies_dropped)]
        for _, _, table in self._namespaces:
            pairs += table.status_pairs()
        return pairs + channel_status(ctl) + clip_status(ctl) + follow_status(ctl, fit_osc_string)

    def _on_status(self, msg: Message, channels, peer, at_frame) -> None:
        args: list[object] = []
        for key, value in self.status_pairs():
            args += [key, value]
        self._reply(peer, f"{self.prefix}/status.reply", args)

    def _on_ping(self, msg: Message, channels, peer, at_frame) -> None:
        try:
            data = encode_message(f"{self.prefix}/pong", msg.args, msg.types)
        except (ParameterError, TypeError):
            data = encode_message(f"{self.prefix}/pong")
        peer.send(data)

    def _on_sync(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (0, 1), "sync id")
        sync_id = int(_number(msg, 0, "sync id")) if msg.args else 0
        if not -(2**31) <= sync_id < 2**31:
            raise ParameterError("sync id must fit in 32 bits")
        worker = self.sync_worker
        if worker is None:
            self.reply_synced(peer, sync_id, self.controller.sync(timeout_s=1.0))
        elif worker.idle and self.controller.sync(timeout_s=0.0):
            self.reply_synced(peer, sync_id, True)  # already applied: answer now
        else:
            worker.submit(peer, sync_id)

    def reply_synced(self, peer: PeerLike, sync_id: int, ok: bool) -> None:
        """Send ``/synced id`` (or an error when the engine did not catch up)."""
        if ok:
            self._reply(peer, f"{self.prefix}/synced", (sync_id,), "i")
        else:
            self._error(
                peer,
                f"{self.prefix}/sync",
                f"engine did not apply the commands before sync {sync_id} in time",
                "osc.sync_timeout",
            )

    def _on_notify(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "1 = subscribe, 0 = unsubscribe")
        on = _flag(msg, 0, "notify")
        if self.notifier is None:
            raise VibsynthError("notifications are not available")
        target = peer.peer if isinstance(peer, ReplyBudget) else peer  # pushes are not replies to this packet
        if on and not self.notifier.subscribe(target):
            raise VibsynthError(f"too many notify subscribers (max {self.notifier.max_subscribers})")
        if not on:
            self.notifier.unsubscribe(target)
        if hasattr(target, "keep_alive"):
            target.keep_alive = on  # a TCP subscriber may stay silent (no idle timeout)
        self._reply(peer, f"{self.prefix}/done", (f"{self.prefix}/notify", int(on)), "si")

    def _on_monitor(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "1 = subscribe (renew within 30 s), 0 = unsubscribe")
        on = _flag(msg, 0, "monitor")
        if self.monitor is None:
            raise VibsynthError("monitoring is not available")
        if isinstance(peer, ReplyBudget):
            raise VibsynthError("use TCP (osc.tcp) to monitor from another host; UDP only from this machine")
        if on:
            self.monitor.subscribe(peer)
        else:
            self.monitor.unsubscribe(peer)
        if hasattr(peer, "keep_alive"):
            peer.keep_alive = on  # a TCP subscriber may stay silent (no idle timeout)
        self._reply(peer, f"{self.prefix}/done", (f"{self.prefix}/monitor", int(on)), "si")

    def _on_learn(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "knob name")
        name = _string(msg, 0, "knob")
        learn = getattr(self.controller, "learn", None)
        if not callable(learn):
            learn = _midi_learn_hook()
        if learn is None or learn(name) is False:
            raise VibsynthError("MIDI learn unavailable (no MIDI input is running)")
        self._reply(peer, f"{self.prefix}/done", (f"{self.prefix}/learn", name), "ss")


def _sender(peer: PeerLike) -> str:
    return describe_sender(getattr(peer, "address", None), getattr(peer, "datagram", True))
