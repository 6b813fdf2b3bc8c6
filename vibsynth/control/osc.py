"""OSC control server: the address space VR apps and live-coding tools drive (see docs/osc.md).

Layers (each its own module, tests use each without a socket):

* :mod:`~vibsynth.control.osc_codec` - wire format (strict, bounded decoder);
* :mod:`~vibsynth.control.osc_address` - address table and OSC 1.0 pattern matching;
* :class:`OscHandler` (here) - one method per address: validates arguments at the edge,
  calls the :class:`~vibsynth.control.controller.Controller`, replies to the sender;
  bundles with future timetags are converted to stream frames (``at_frame``);
* :mod:`~vibsynth.control.osc_server` - UDP (and optional TCP/SLIP) transports;
* :mod:`~vibsynth.control.osc_workers` - ``/notify`` pushes and deferred ``/sync`` replies.

The service calls :func:`add_arguments` and :func:`create` (adapter contract of
:mod:`vibsynth.control`).
"""
from __future__ import annotations

import argparse
import bisect
import functools
import ipaddress
import logging
import math
import re
import threading
import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Iterable, Sequence

from vibsynth import __version__
from vibsynth.control.controller import Controller, KnobEvent, check_finite, check_range
from vibsynth.control.osc_address import GLOBAL_METHODS, AddressSpace, normalize_prefix
from vibsynth.control.osc_fast import make_receiver
from vibsynth.control.osc_codec import (
    IMMEDIATE,
    MalformedPacket,
    Message,
    decode_packet,
    encode_message,
    iter_messages,
    ntp_to_unix,
)
from vibsynth.control.osc_server import (
    DEFAULT_RCVBUF,
    TCP_IDLE_TIMEOUT_S,
    TCP_MAX_CONNECTIONS,
    TCP_MAX_PER_PEER,
    TcpSlipTransport,
    TransportStats,
    UdpTransport,
    resolve_allow_list,
)
from vibsynth.control.osc_workers import Notifier, PeerLike, SyncWorker, setter_message
from vibsynth.errors import ConfigError, ParameterError, PresetError, ScheduleFullError, VibsynthError

__all__ = [
    "OscArgumentError",
    "SpeedCurve",
    "StreamClock",
    "OscStats",
    "OscHandler",
    "OscServer",
    "REPLY_AMPLIFICATION",
    "ReplyBudget",
    "redact_paths",
    "fit_osc_string",
    "is_loopback",
    "add_arguments",
    "create",
]

log = logging.getLogger(__name__)

SOURCE = "osc"
SPEED_SOURCE = "osc-speed"
_NUMERIC = frozenset("ifdh")
_COALESCED = frozenset({"intensity", "balance", "texture", "speed"})
_LOOPBACK = {"127.0.0.1", "::1", "localhost"}

REPLY_AMPLIFICATION = 3
"""UDP replies to a client on another host total at most this many times the bytes of the
packet that caused them (the anti-amplification limit of QUIC, RFC 9000 section 8.1): a
forged source address cannot turn the server into an amplifier. Error replies are cut to
fit; other replies that do not fit are not sent (counted) and an error says why. Clients on
this host and TCP clients (whose address the handshake proved) are not limited."""


@functools.lru_cache(maxsize=1024)
def is_loopback(host: str) -> bool:
    """Is ``host`` (an IP address string, IPv4-mapped IPv6 included) a loopback address?"""
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return ip.is_loopback


# An absolute path: /a/b, ~/a, C:\a or C:/a, not preceded by a word character or a path
# character (so "mm/s" and "a/b" are left alone). One character class repeated: linear time.
_PATH = re.compile(r"(?<![\w.~/\\-])(?:~|[A-Za-z]:)?[/\\][^\s'\"`,;:()\[\]{}<>]+")
_OWN_PARTS = frozenset(GLOBAL_METHODS) | {"ch"}


def _is_osc_address(token: str, prefix: str) -> bool:
    if prefix:
        return token == prefix or token.startswith(prefix + "/")
    parts = token.split("/")
    return "\\" not in token and len(parts) > 1 and parts[1] in _OWN_PARTS


def redact_paths(text: str, prefix: str = "/vibsynth") -> str:
    """Replace every absolute file-system path in ``text`` by its base name (``<path>`` if none).

    Error messages sent to the network must not disclose where files live (user names,
    folders); ``/home/ana/.config/vibsynth/presets/x.yaml:3: ...`` becomes ``x.yaml:3: ...``.
    OSC addresses under ``prefix`` (e.g. ``/vibsynth/ch/1/intensity``) are kept.
    """
    def replace(match: re.Match[str]) -> str:
        token = match.group(0)
        if _is_osc_address(token, prefix):
            return token
        name = token.rstrip("/\\").replace("\\", "/").rsplit("/", 1)[-1]
        return name if name and name != "~" and not name.endswith(":") else "<path>"

    return _PATH.sub(replace, text)


def _osc_string_size(text: str) -> int:
    """Bytes ``text`` takes in an OSC message (UTF-8, NUL-terminated, padded to 4)."""
    return (len(text.encode("utf-8")) // 4 + 1) * 4


def fit_osc_string(text: str, size: int) -> str:
    """``text``, cut (ending in ``...``) so that it takes at most ``size`` bytes in an OSC message.

    ``size`` >= 4 (the empty string's size).
    """
    limit = (size // 4) * 4 - 1  # longest UTF-8 text that fits
    raw = text.encode("utf-8")
    if len(raw) <= limit:
        return text
    if limit < 3:
        return raw[:max(limit, 0)].decode("utf-8", "ignore")
    return raw[:limit - 3].decode("utf-8", "ignore") + "..."


class ReplyBudget:
    """A UDP peer on another host, seen while one request is handled: its replies share a byte budget.

    Parameters
    ----------
    peer : PeerLike
        The real peer.
    limit : int
        Bytes all replies to this request may take (:data:`REPLY_AMPLIFICATION` x its size).
    on_refused : callable
        ``on_refused(budget, size)`` when a reply of ``size`` bytes does not fit (not sent).
    """

    __slots__ = ("peer", "limit", "room", "request", "refused", "_on_refused")

    def __init__(self, peer: PeerLike, limit: int, on_refused: Callable[["ReplyBudget", int], None]) -> None:
        self.peer = peer
        self.limit = limit
        self.room = limit
        self.request = ""
        self.refused = False
        self._on_refused = on_refused

    @property
    def key(self) -> tuple:
        return self.peer.key

    @property
    def address(self) -> tuple[str, int] | None:
        return getattr(self.peer, "address", None)

    def send(self, data: bytes) -> bool:
        """Send when it fits in what is left of the budget; otherwise report it and send nothing."""
        if len(data) > self.room:
            self._on_refused(self, len(data))
            return False
        self.room -= len(data)
        return self.peer.send(data)


class OscArgumentError(ParameterError):
    """Wrong number or type of OSC arguments."""


# ---------------------------------------------------------------------- speed
class SpeedCurve:
    """Scanning speed (mm/s) -> intensity, piecewise linear; optional balance shift.

    Parameters
    ----------
    points : sequence of (mm/s, intensity)
        Strictly increasing speeds >= 0, intensities in [0, 1]. Below the first point the
        first intensity applies, above the last the last one. The default
        ``[[0, 0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1]]`` is silent at rest.
    balance_per_decade : float
        Balance added per decade of speed above 100 mm/s (0 = speed leaves balance alone).

    Raises
    ------
    ConfigError
        If the points are not a valid curve.
    """

    REFERENCE_MM_S = 100.0

    def __init__(self, points: Sequence[Sequence[float]], balance_per_decade: float = 0.0) -> None:
        try:
            pts = [(float(s), float(v)) for s, v in points]
            self.balance_per_decade = float(balance_per_decade)
        except (TypeError, ValueError):
            raise ConfigError("speed.curve must be a list of [mm/s, intensity] pairs") from None
        if len(pts) < 1 or not all(math.isfinite(s) and math.isfinite(v) for s, v in pts):
            raise ConfigError("speed.curve needs at least one finite [mm/s, intensity] point")
        if any(s < 0 or not 0.0 <= v <= 1.0 for s, v in pts):
            raise ConfigError("speed.curve speeds must be >= 0 and intensities within [0, 1]")
        if any(b[0] <= a[0] for a, b in zip(pts, pts[1:])):
            raise ConfigError("speed.curve speeds must be strictly increasing")
        if not math.isfinite(self.balance_per_decade):
            raise ConfigError("speed.balance_per_decade must be finite")
        self.speeds = [s for s, _ in pts]
        self.levels = [v for _, v in pts]

    def intensity(self, speed: float) -> float:
        """Intensity for a speed in mm/s (>= 0)."""
        xs, ys = self.speeds, self.levels
        if speed <= xs[0]:
            return ys[0]
        if speed >= xs[-1]:
            return ys[-1]
        i = bisect.bisect_right(xs, speed)
        x0, x1, y0, y1 = xs[i - 1], xs[i], ys[i - 1], ys[i]
        return y0 + (y1 - y0) * (speed - x0) / (x1 - x0)

    def balance_shift(self, speed: float) -> float:
        """Balance offset for a speed (0 at and below 100 mm/s)."""
        if self.balance_per_decade == 0.0 or speed <= self.REFERENCE_MM_S:
            return 0.0
        return self.balance_per_decade * math.log10(speed / self.REFERENCE_MM_S)


# ---------------------------------------------------------------------- clock
class StreamClock:
    """Maps wall time (``time.time()``) to the engine's stream position (frames).

    The engine publishes ``frame_position`` in whole blocks, so one sample
    ``frame/fs - wall`` is late by up to a block; the estimate keeps the largest
    (least late) offset seen, decaying slowly (``drift`` s/s, 1000 ppm: more than sound
    cards and JACK's dummy driver drift) so that the drift between the audio clock and
    the system clock is followed, and resets when the stream jumps (restart). The OSC
    handler samples it with every batch of packets it receives.
    """

    def __init__(self, engine: Any, *, drift: float = 1e-3, reset_s: float = 0.25,
                 wall: Callable[[], float] = time.time) -> None:
        self.engine = engine
        self.drift = drift
        self.reset_s = reset_s
        self.wall = wall
        self._offset: float | None = None
        self._last_wall = 0.0

    def sample(self) -> tuple[int, float]:
        """Read the engine clock once; return ``(frame_position, wall_time)``."""
        frame = int(self.engine.frame_position)
        now = self.wall()
        offset = frame / float(self.engine.fs) - now
        est = self._offset
        if est is None:
            est = offset
        else:
            est -= self.drift * max(0.0, now - self._last_wall)
            if offset > est or offset < est - self.reset_s:
                est = offset
        self._offset = est
        self._last_wall = now
        return frame, now

    def frame_at(self, unix_time: float) -> tuple[int, int]:
        """Stream frame for a wall time; returns ``(frame, current_frame_position)``."""
        current, _ = self.sample()
        assert self._offset is not None
        return int(round((unix_time + self._offset) * float(self.engine.fs))), current


# ---------------------------------------------------------------------- handler
@dataclass
class OscStats:
    """Counters of the OSC handler (written on the receive thread only)."""

    messages: int = 0
    bundles: int = 0
    scheduled: int = 0
    malformed: int = 0
    errors: int = 0
    error_replies_suppressed: int = 0
    replies_truncated: int = 0   # error replies cut to the UDP reply budget
    replies_dropped: int = 0     # replies not sent: over the UDP reply budget


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


def _arg_count(msg: Message, allowed: Sequence[int], what: str) -> None:
    if len(msg.args) not in allowed:
        want = " or ".join(str(n) for n in allowed)
        raise OscArgumentError(f"expects {want} argument(s) ({what}), got {len(msg.args)}")


def _number(msg: Message, index: int, name: str) -> float:
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag not in _NUMERIC:
        raise OscArgumentError(f"{name} must be a number (OSC type i, f, d or h), got type {tag!r}")
    return check_finite(name, msg.args[index])


def _string(msg: Message, index: int, name: str) -> str:
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag not in "sS":
        raise OscArgumentError(f"{name} must be a string (OSC type s), got type {tag!r}")
    return str(msg.args[index])


def _flag(msg: Message, index: int, name: str) -> bool:
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag in "TF":
        return bool(msg.args[index])
    value = _number(msg, index, name)
    if value not in (0.0, 1.0):
        raise ParameterError(f"{name} must be 0 or 1, got {value:g}")
    return value == 1.0


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
        self.clock = StreamClock(self.engine)
        self.stats = OscStats()
        self._error_bucket = _TokenBucket(error_reply_rate)
        self._error_address = f"{self.prefix}/error"
        self._methods: dict[str, Callable[[Message, tuple[int, ...] | None, PeerLike, int | None], None]] = {
            "intensity": self._on_intensity, "balance": self._on_balance, "texture": self._on_texture,
            "glide": self._on_glide, "mute": self._on_mute, "panic": self._on_panic, "preset": self._on_preset,
            "speed": self._on_speed, "get": self._on_get, "status": self._on_status, "ping": self._on_ping,
            "sync": self._on_sync, "notify": self._on_notify, "learn": self._on_learn,
        }
        # balance set by anything but /speed: the base that the speed shift is added to
        self._base_balance = [s.balance for s in controller.state()]
        # coalescing of immediate knob moves within one receive batch (see handle_batch)
        self._batching = False
        self._pending: dict[tuple, Callable[[], object]] = {}
        self._base_lock = threading.Lock()
        self._unsubscribe: Callable[[], None] | None = None
        if self.speed_curve.balance_per_decade != 0.0:
            self._unsubscribe = controller.subscribe(self._track_balance)

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
        if isinstance(peer, ReplyBudget):
            peer.request = msg.address
        try:
            routes = self.space.match(msg.address)
        except ParameterError as exc:
            self._error(peer, msg.address, str(exc), "osc.bad_pattern")
            return
        if not routes:
            self._error(peer, msg.address, "unknown address", "osc.unknown_address")
            return
        if len(routes) == 1:
            route = routes[0]
            calls = [(route.method, None if route.channel is None else (route.channel,))]
        else:
            calls = self.space.group(routes)
        for method, channels in calls:
            if self._pending and (at_frame is not None or method not in _COALESCED):
                self.flush()  # keep order with everything that is not coalesced
            try:
                self._methods[method](msg, channels, peer, at_frame)
            except OscArgumentError as exc:
                self._error(peer, msg.address, f"{method}: {exc}", "osc.bad_arguments")
            except PresetError as exc:
                self._error(peer, msg.address, str(exc), "osc.preset")
            except ScheduleFullError as exc:
                self._error(peer, msg.address, str(exc), "osc.schedule_full")
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
            return (f"timetag is {ahead:.3g} s ahead, beyond the schedule horizon of {self.horizon_s:g} s "
                    "(osc.schedule_horizon_s); message rejected")
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
        self._error(budget, budget.request, f"reply of {size} bytes not sent: replies to a UDP client on another "
                    f"host total at most {REPLY_AMPLIFICATION}x the request ({budget.limit} bytes); use TCP "
                    "(osc.tcp) or a longer request", "osc.reply_limit")

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
            self._defer((name, channels), lambda: self.controller.set_knob(name, value, channels=channels, source=SOURCE))
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
            self._defer(("texture", channels), lambda: self.controller.set_texture(
                intensity, balance, channels=channels, source=SOURCE))
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
            self.controller.set_knob("intensity", curve.intensity(speed), channels=channels,
                                     at_frame=at_frame, source=SOURCE)
            return
        self._set_knob("intensity", curve.intensity(speed), channels, at_frame)

    # -------------------------------------------------------------- queries
    def _on_get(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "setting name")
        name = _string(msg, 0, "setting")
        fields = ("intensity", "balance", "glide", "mute", "preset")
        if name not in fields and name != "texture":
            raise ParameterError(f"unknown setting {name!r}; known: {', '.join(fields + ('texture',))}")
        states = self.controller.state()
        chans = range(len(states)) if channels is None else channels

        def values(ch: int) -> tuple:
            s = states[ch]
            if name == "texture":
                return (s.intensity, s.balance)
            return ({"intensity": s.intensity, "balance": s.balance, "glide": s.glide_s,
                     "mute": s.muted, "preset": s.preset}[name],)

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
        """The ``/status.reply`` content as ``(key, value)`` pairs (-1 = not known)."""
        engine = self.engine
        ctl = self.controller
        pairs: list[tuple[str, object]] = [
            ("version", __version__),
            ("channels", int(ctl.channels)),
            ("rate", float(getattr(engine, "fs", -1.0))),
            ("block_size", int(_engine_stat(engine, ("block_size", "blocksize", "block_frames"), self.block_size or -1))),
            ("underflows", int(_engine_stat(engine, ("underflows", "xruns", "underruns"), -1))),
            ("load", float(_engine_stat(engine, ("render_load", "load_avg", "load", "cpu_load"), -1.0))),
            ("load_peak", float(_engine_stat(engine, ("load_peak",), -1.0))),
            ("late_commands", int(_engine_stat(engine, ("late_commands",), -1))),
            ("scheduled_pending", int(_engine_stat(engine, ("pending",), -1))),
            ("schedule_full", int(_engine_stat(engine, ("schedule_full",), -1))),
            ("uptime", float(time.monotonic() - ctl.started_at)),
            ("frame", int(_engine_stat(engine, ("frame_position",), -1))),
            ("messages", self.stats.messages),
            ("scheduled", self.stats.scheduled),
            ("malformed", self.stats.malformed),
            ("errors", int(sum(ctl.error_counts.values()))),
            ("subscribers", len(self.notifier) if self.notifier is not None else 0),
        ]
        # The audio output (set by the service as controller.output): "streaming", or
        # "device lost" with the reason while it is retried.
        output = getattr(ctl, "output", None)
        if output is not None:
            pairs += [("output", str(getattr(output, "state", ""))),
                      ("output_reason", str(getattr(output, "state_reason", "")))]
        if self.extra_status is not None:
            pairs.extend(self.extra_status())
        pairs += [("replies_truncated", self.stats.replies_truncated), ("replies_dropped", self.stats.replies_dropped)]
        for ch, s in enumerate(ctl.state()):
            pairs += [(f"ch{ch + 1}.intensity", float(s.intensity)), (f"ch{ch + 1}.balance", float(s.balance)),
                      (f"ch{ch + 1}.glide", float(s.glide_s * 1000.0)), (f"ch{ch + 1}.mute", int(s.muted)),
                      (f"ch{ch + 1}.preset", s.preset or "")]
        return pairs

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
            self._error(peer, f"{self.prefix}/sync", f"engine did not apply the commands before sync {sync_id} in time",
                        "osc.sync_timeout")

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

    def _on_learn(self, msg: Message, channels, peer, at_frame) -> None:
        _arg_count(msg, (1,), "knob name")
        name = _string(msg, 0, "knob")
        learn = getattr(self.controller, "learn", None)
        if not callable(learn):
            learn = _midi_learn_hook()
        if learn is None or learn(name) is False:
            raise VibsynthError("MIDI learn unavailable (no MIDI input is running)")
        self._reply(peer, f"{self.prefix}/done", (f"{self.prefix}/learn", name), "ss")


def _midi_learn_hook() -> Callable[[str], bool] | None:
    """``vibsynth.control.midi.learn`` when the MIDI adapter is installed, else None."""
    try:
        from vibsynth.control import midi
    except Exception:  # noqa: BLE001 - MIDI is optional (python-rtmidi may be missing)
        return None
    hook = getattr(midi, "learn", None)
    return hook if callable(hook) else None


def _engine_stat(engine: Any, names: Sequence[str], default: float) -> float:
    """First available engine statistic among ``names`` (attributes or a ``stats`` mapping/method)."""
    stats = getattr(engine, "stats", None)
    try:
        if callable(stats):
            stats = stats()
    except Exception:  # noqa: BLE001 - the engine is optional here, never let status fail
        stats = None
    for name in names:
        value = None
        if isinstance(stats, dict):
            value = stats.get(name)
        elif stats is not None:
            value = getattr(stats, name, None)
        if value is None:
            value = getattr(engine, name, None)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return value
    return default


# ---------------------------------------------------------------------- server
class OscServer:
    """The OSC control server: transports + handler + workers (the adapter's ControlServer).

    Parameters
    ----------
    controller : Controller
    host, port : str, int
    prefix, allow, reply_port, schedule_horizon_s, notify_rate_hz, tcp, speed_curve
        See the ``osc:`` config section and docs/osc.md.
    tcp_max_connections, tcp_max_per_peer, tcp_idle_timeout_s
        TCP connection limits (see :class:`~vibsynth.control.osc_server.TcpSlipTransport`).
    block_size : int, optional
        Reported in status when the engine does not say.
    """

    name = "osc"

    def __init__(
        self,
        controller: Controller,
        *,
        host: str = "127.0.0.1",
        port: int = 9570,
        prefix: str = "/vibsynth",
        allow: Sequence[str] | None = None,
        reply_port: int | None = None,
        schedule_horizon_s: float = 10.0,
        notify_rate_hz: float = 30.0,
        tcp: bool = False,
        speed_curve: SpeedCurve | None = None,
        block_size: int | None = None,
        rcvbuf: int = DEFAULT_RCVBUF,
        tcp_max_connections: int = TCP_MAX_CONNECTIONS,
        tcp_max_per_peer: int = TCP_MAX_PER_PEER,
        tcp_idle_timeout_s: float = TCP_IDLE_TIMEOUT_S,
    ) -> None:
        self.controller = controller
        self.stats = TransportStats()
        allow_set = resolve_allow_list(allow)
        prefix = normalize_prefix(prefix)
        self.notifier = Notifier(controller, prefix, rate_hz=notify_rate_hz)
        self.sync_worker = SyncWorker(controller, self._reply_synced, timeout_s=schedule_horizon_s + 2.0)
        self.handler = OscHandler(
            controller, prefix=prefix, speed_curve=speed_curve, schedule_horizon_s=schedule_horizon_s,
            notifier=self.notifier, sync_worker=self.sync_worker, block_size=block_size,
            extra_status=self._status_extras,
        )
        self.udp = UdpTransport(host, port, self.handler.handle_batch, allow=allow_set, reply_port=reply_port,
                                rcvbuf=rcvbuf, stats=self.stats,
                                receiver_factory=partial(make_receiver, controller=controller, space=self.handler.space))
        self.tcp = (TcpSlipTransport(host, port, self.handler.handle_batch, allow=allow_set, stats=self.stats,
                                     on_close=self.notifier.unsubscribe, max_connections=tcp_max_connections,
                                     max_per_peer=tcp_max_per_peer, idle_timeout_s=tcp_idle_timeout_s)
                    if tcp else None)
        self._started = False

    def _reply_synced(self, peer: PeerLike, sync_id: int, ok: bool) -> None:
        self.handler.reply_synced(peer, sync_id, ok)

    def _status_extras(self) -> list[tuple[str, object]]:
        s = self.stats
        return self._transport_status() + [("tcp_refused", s.tcp_refused), ("tcp_idle_closed", s.tcp_idle_closed)]

    def counters(self) -> dict[str, int]:
        """Transport counters of both transports: the TCP ones in :attr:`stats`, the UDP ones in
        the compiled receive loop (``fast_path``: messages it handled without Python)."""
        s, udp = self.stats, self.udp.counters()
        return {"packets": s.packets + udp.get("packets", 0), "bytes": s.bytes + udp.get("bytes", 0),
                "denied": s.denied + udp.get("denied", 0), "fast_path": udp.get("fast", 0),
                "replies": s.replies, "send_errors": s.send_errors}

    def _transport_status(self) -> list[tuple[str, object]]:
        c = self.counters()
        return [("packets", c["packets"]), ("denied", c["denied"]), ("fast_path", c["fast_path"]),
                ("replies", c["replies"]), ("send_errors", c["send_errors"]), ("rcvbuf", self.udp.rcvbuf)]

    @property
    def port(self) -> int:
        """The bound UDP port (useful with port 0)."""
        return self.udp.port

    def start(self) -> None:
        """Bind the sockets and start the receive, notify and sync threads.

        Raises
        ------
        ConfigError
            If the address cannot be bound (e.g. port in use).
        """
        try:
            self.udp.open()
            if self.tcp is not None:
                self.tcp.port = self.udp.port
                self.tcp.open()
        except OSError as exc:
            self.udp.stop()
            raise ConfigError(f"OSC: cannot listen on {self.udp.host}:{self.udp.port}: {exc.strerror or exc} "
                              "(set osc.port or --osc-port)") from None
        self.notifier.start()
        self.sync_worker.start()
        self.udp.start()
        if self.tcp is not None:
            self.tcp.start()
        self._started = True
        log.info("%s", self.describe())

    def stop(self) -> None:
        """Stop every thread and close the sockets (idempotent)."""
        self.udp.stop()
        if self.tcp is not None:
            self.tcp.stop()
        self.notifier.stop()
        self.sync_worker.stop()
        self.handler.close()
        self._started = False

    def describe(self) -> str:
        """One line for the start-up banner."""
        host = self.udp.host
        text = f"OSC on udp://{host}:{self.udp.port}{self.handler.prefix or '/'}"
        if self.tcp is not None:
            text += f" and tcp://{host}:{self.udp.port} (SLIP)"
        if self.udp.rcvbuf:
            text += f", receive buffer {self.udp.rcvbuf // 1024} KiB"
        if host not in _LOOPBACK:
            text += ", reachable from the network" + (" (allow-list)" if self.udp.allow else "")
        return text


# ---------------------------------------------------------------------- adapter contract
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--osc-port``, ``--osc-host`` and ``--no-osc`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("OSC")
    group.add_argument("--osc-port", type=int, default=None, metavar="PORT",
                       help="UDP port of the OSC server (default: osc.port, 9570)")
    group.add_argument("--osc-host", default=None, metavar="HOST",
                       help="address to listen on (default: osc.host, 127.0.0.1; 0.0.0.0 = every interface)")
    group.add_argument("--no-osc", action="store_true", default=False, help="do not start the OSC server")


def _port(value: Any, key: str) -> int:
    try:
        port = int(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{key} must be a port number, got {value!r}") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"{key} {port} is outside [0, 65535]")
    return port


def create(config: Any, args: argparse.Namespace | None, controller: Controller, presets: Any = None) -> OscServer | None:
    """Build (not start) the OSC server from the config and flags; None when disabled.

    Parameters
    ----------
    config : Config
        Effective configuration (``osc``, ``speed`` and ``audio`` sections are read).
    args : argparse.Namespace or None
        Parsed ``vibsynth serve`` flags (``--osc-port``, ``--osc-host``, ``--no-osc``).
    controller : Controller
    presets : object, optional
        The preset library (unused: presets are resolved by the controller).

    Raises
    ------
    ConfigError
        For invalid ``osc``/``speed`` settings.
    """
    data = getattr(config, "data", config) or {}
    osc = dict(data.get("osc") or {})
    if getattr(args, "no_osc", False) or not osc.get("enabled", True):
        log.info("OSC server disabled (%s)", "--no-osc" if getattr(args, "no_osc", False) else "osc.enabled: false")
        return None
    host = getattr(args, "osc_host", None) or osc.get("host") or "127.0.0.1"
    port_flag = getattr(args, "osc_port", None)
    port = _port(port_flag if port_flag is not None else osc.get("port", 9570), "osc.port")
    reply_port = osc.get("reply_port")
    reply_port = None if reply_port in (None, "", 0) else _port(reply_port, "osc.reply_port")
    speed = dict(data.get("speed") or {})
    curve = SpeedCurve(speed.get("curve", [[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]]),
                       speed.get("balance_per_decade", 0.0) or 0.0)
    try:
        horizon = float(osc.get("schedule_horizon_s", 10.0))
        rate = float(osc.get("notify_rate_hz", 30.0))
    except (TypeError, ValueError):
        raise ConfigError("osc.schedule_horizon_s and osc.notify_rate_hz must be numbers") from None
    if not (math.isfinite(horizon) and 0.0 <= horizon <= 3600.0):
        raise ConfigError(f"osc.schedule_horizon_s {horizon:g} is outside [0, 3600]")
    if not (math.isfinite(rate) and 0.0 < rate <= 1000.0):
        raise ConfigError(f"osc.notify_rate_hz {rate:g} is outside (0, 1000]")
    allow = osc.get("allow") or []
    if isinstance(allow, str):
        allow = [allow]
    tcp_limits = _tcp_limits(osc)
    block = (data.get("audio") or {}).get("block_size")
    return OscServer(
        controller, host=str(host), port=port, prefix=osc.get("prefix", "/vibsynth"), allow=allow,
        reply_port=reply_port, schedule_horizon_s=horizon, notify_rate_hz=rate, tcp=bool(osc.get("tcp", False)),
        speed_curve=curve, block_size=int(block) if isinstance(block, int) else None, **tcp_limits,
    )


def _tcp_limits(osc: dict) -> dict[str, Any]:
    """``tcp_max_connections``, ``tcp_max_per_peer``, ``tcp_idle_timeout_s`` from the ``osc`` section.

    Raises
    ------
    ConfigError
        For a value outside its range.
    """
    out: dict[str, Any] = {}
    for key, default, low, high in (("tcp_max_connections", TCP_MAX_CONNECTIONS, 1, 1024),
                                    ("tcp_max_per_peer", TCP_MAX_PER_PEER, 1, 1024)):
        value = osc.get(key, default)
        if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
            raise ConfigError(f"osc.{key} {value!r} is not an integer in [{low}, {high}]")
        out[key] = value
    idle = osc.get("tcp_idle_timeout_s", TCP_IDLE_TIMEOUT_S)
    if not isinstance(idle, (int, float)) or isinstance(idle, bool) or not (math.isfinite(idle) and 0 < idle <= 86400):
        raise ConfigError(f"osc.tcp_idle_timeout_s {idle!r} is not a number in (0, 86400] s")
    out["tcp_idle_timeout_s"] = float(idle)
    return out
