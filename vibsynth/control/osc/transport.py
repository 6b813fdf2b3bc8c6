"""OSC transports: UDP (a compiled receive loop, large receive buffer) and optional TCP with SLIP framing.

Transports know nothing of OSC addresses: they receive packets, drop those from
clients outside the allow-list (counted), and hand batches of ``(data, peer)`` to a
callback, so the handler can coalesce moves that arrived together. The UDP receive loop is
compiled (:mod:`vibsynth.control.osc._fast`): it never waits for the GIL and, when the
OSC server gives it a fast path (:mod:`vibsynth.control.osc.fast`), puts the common knob
messages straight into the engine's command ring. What is for Python it queues (seconds of a
flood; a datagram finding the queue full is counted in ``queue_full``), and a second, normally
scheduled thread hands the queue to the callback in arrival order, so a busy interpreter or a
slow handler never stops the socket being read. The loop runs under real-time scheduling
(SCHED_FIFO at :data:`RECEIVE_PRIORITY`, below the audio threads) where the system allows it,
so a datagram wakes it at once even when every core is busy, and before the next block
starts. The TCP transport runs its callback on its own selector thread.
``peer.send(data)`` replies to the sender (UDP: its address, or the configured reply port on
its host; TCP: the same connection).

Limits: TCP connections are bounded (:data:`TCP_MAX_CONNECTIONS` in all,
:data:`TCP_MAX_PER_PEER` per client address) and closed after :data:`TCP_IDLE_TIMEOUT_S`
without a complete packet, so stalled clients cannot lock others out. The allow-list
is parsed by :func:`parse_allow_list`, the very function that validates ``osc.allow``
in the config, so a config that passes always starts the server.
"""

from __future__ import annotations

import logging
import os
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from vibsynth.control.osc.fast import make_receiver
from vibsynth.settings.allow_list import AllowList
from vibsynth.settings.models_config import Osc

__all__ = [
    "TransportStats",
    "UdpPeer",
    "TcpPeer",
    "UdpTransport",
    "TcpTransport",
    "slip_encode",
    "length_encode",
    "LengthPrefixDecoder",
    "FramingDetector",
    "SlipDecoder",
    "TCP_MAX_CONNECTIONS",
    "TCP_MAX_PER_PEER",
    "TCP_IDLE_TIMEOUT_S",
    "DEFAULT_RCVBUF",
    "RECEIVE_PRIORITY",
]

log = logging.getLogger(__name__)

DEFAULT_RCVBUF = 4 * 1024 * 1024
MAX_DATAGRAM = 65536

# The TCP limits' defaults are the settings' (one definition: vibsynth/settings/models_config.py).
TCP_MAX_CONNECTIONS: int = Osc.model_fields["tcp_max_connections"].default
"""Open TCP connections in all (``osc.tcp_max_connections``); twice the 32 /notify subscribers."""
TCP_MAX_PER_PEER: int = Osc.model_fields["tcp_max_per_peer"].default
"""Open TCP connections from one client IP address (``osc.tcp_max_per_peer``)."""
TCP_IDLE_TIMEOUT_S: float = Osc.model_fields["tcp_idle_timeout_s"].default
"""A TCP connection without a complete packet for this long is closed (``osc.tcp_idle_timeout_s``)."""
_POLL_S = 0.25

RECEIVE_PRIORITY = 1
"""SCHED_FIFO priority of the UDP receive loop: above every normally scheduled thread, below
JACK's and PortAudio's audio threads (0 = normal scheduling)."""


def _realtime(priority: int) -> bool:
    """Put the calling thread under SCHED_FIFO ``priority``; False where not allowed or not POSIX."""
    if not hasattr(os, "sched_setscheduler") or priority <= 0:  # Windows, macOS
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # pid 0: this thread (Linux)
    except (OSError, ValueError):  # no CAP_SYS_NICE / RLIMIT_RTPRIO, or not supported
        return False
    return True


BatchHandler = Callable[[list], None]
"""``handler([(data, peer), ...])``, called on the receive thread (UDP: on its delivery thread)."""

ReceiverFactory = Callable[[int, Callable[[list], None], Any], Any]
"""``factory(fd, on_datagrams, allow) -> receiver`` with ``run()``, ``deliver(timeout_s)``, ``stop()``,
``counters()``."""


@dataclass
class TransportStats:
    """Counters kept by the receive threads (read by status queries without a lock)."""

    packets: int = 0
    bytes: int = 0
    denied: int = 0
    send_errors: int = 0
    replies: int = 0
    tcp_connections: int = 0
    oversized_frames: int = 0
    handler_errors: int = 0
    tcp_refused: int = 0
    tcp_idle_closed: int = 0
    receive_failed: int = 0


@dataclass(frozen=True, slots=True)
class UdpPeer:
    """A UDP client: replies go to ``reply_to`` through the server socket."""

    address: tuple[str, int]
    reply_to: tuple[str, int]
    transport: UdpTransport = field(compare=False, hash=False, repr=False)
    datagram = True  # replies to off-host peers are size-limited (OscHandler)

    @property
    def key(self) -> tuple:
        return ("udp", self.reply_to)

    def send(self, data: bytes) -> bool:
        return self.transport.send_to(data, self.reply_to)


class TcpPeer:
    """A TCP client connection: replies go back on the same connection, framed as the client frames.

    ``keep_alive`` (set for /notify subscribers) exempts it from the idle timeout.
    """

    datagram = False

    def __init__(self, sock: socket.socket, address: tuple[str, int], stats: TransportStats) -> None:
        self.sock = sock
        self.address = address
        self.closed = False
        self.keep_alive = False
        self.encode: Callable[[bytes], bytes] = slip_encode  # set from the client's framing
        self._stats = stats
        self._lock = threading.Lock()

    @property
    def key(self) -> tuple:
        return ("tcp", self.address)

    def send(self, data: bytes) -> bool:
        """Queue a frame on the (non-blocking) connection; a client that stopped reading is dropped."""
        if self.closed:
            return False
        frame = self.encode(data)
        try:
            with self._lock:
                self.sock.sendall(frame)
            self._stats.replies += 1
            return True
        except OSError:  # BlockingIOError: its buffer is full (possibly mid-frame): drop it
            self._stats.send_errors += 1
            self.closed = True
            return False


# ---------------------------------------------------------------------- SLIP
_END, _ESC, _ESC_END, _ESC_ESC = 0xC0, 0xDB, 0xDC, 0xDD


def slip_encode(data: bytes) -> bytes:
    """Frame a packet with SLIP (RFC 1055, double-END as OSC 1.1 recommends)."""
    body = data.replace(b"\xdb", b"\xdb\xdd").replace(b"\xc0", b"\xdb\xdc")
    return b"\xc0" + body + b"\xc0"


class SlipDecoder:
    """Incremental SLIP decoder; frames longer than ``max_frame`` are discarded (counted)."""

    def __init__(self, max_frame: int = MAX_DATAGRAM) -> None:
        self.max_frame = max_frame
        self._buf = bytearray()
        self._escape = False
        self._overflow = False
        self.oversized = 0

    @property
    def pending(self) -> bool:
        """True while part of a frame has been received (a frame is open)."""
        return bool(self._buf) or self._escape or self._overflow

    def feed(self, chunk: bytes) -> list[bytes]:
        """Add received bytes; return the complete frames (possibly none)."""
        frames = []
        for byte in chunk:
            if byte == _END:
                if self._buf and not self._overflow:
                    frames.append(bytes(self._buf))
                self._buf.clear()
                self._escape = self._overflow = False
                continue
            if self._escape:
                byte = _END if byte == _ESC_END else _ESC if byte == _ESC_ESC else byte
                self._escape = False
            elif byte == _ESC:
                self._escape = True
                continue
            if len(self._buf) >= self.max_frame:
                if not self._overflow:
                    self.oversized += 1
                self._overflow = True
                continue
            self._buf.append(byte)
        return frames


def length_encode(data: bytes) -> bytes:
    """Frame a packet with a 32-bit big-endian length prefix (OSC 1.0 over TCP; liblo's default)."""
    return len(data).to_bytes(4, "big") + data


class LengthPrefixDecoder:
    """Incremental decoder of length-prefixed frames; frames longer than ``max_frame`` are skipped (counted).

    The bytes of an oversized frame are counted off as they arrive, never stored, so a client
    announcing 4 GB costs no memory.
    """

    def __init__(self, max_frame: int = MAX_DATAGRAM) -> None:
        self.max_frame = max_frame
        self._buf = bytearray()
        self._skip = 0
        self.oversized = 0

    @property
    def pending(self) -> bool:
        """True while part of a frame (or of its length) has been received."""
        return bool(self._buf) or self._skip > 0

    def feed(self, chunk: bytes) -> list[bytes]:
        """Add received bytes; return the complete frames (possibly none)."""
        frames = []
        view = memoryview(chunk)
        while view:
            if self._skip:
                n = min(self._skip, len(view))
                self._skip -= n
                view = view[n:]
                continue
            self._buf += view
            view = view[len(view) :]
            while len(self._buf) >= 4:
                size = int.from_bytes(self._buf[:4], "big")
                if size > self.max_frame:
                    self.oversized += 1
                    rest = len(self._buf) - 4
                    self._skip = max(0, size - rest)
                    del self._buf[: 4 + min(size, rest)]
                    if self._skip:
                        break
                    continue
                if len(self._buf) < 4 + size:
                    break
                if size:
                    frames.append(bytes(self._buf[4 : 4 + size]))
                del self._buf[: 4 + size]
        return frames


class FramingDetector:
    """Decoder of a TCP connection whose framing is told by its first byte.

    OSC 1.1 clients frame with SLIP (the first byte is END, 0xC0, or a packet's first byte,
    ``/`` or ``#``); OSC 1.0 clients such as liblo's ``oscsend osc.tcp://...`` prefix each
    packet with its length (a big-endian count, whose first byte is 0 for any frame under
    16 MiB). Once detected the framing holds for the connection, and replies use it too.
    """

    def __init__(self, max_frame: int = MAX_DATAGRAM) -> None:
        self.max_frame = max_frame
        self.framing: str | None = None
        self._decoder: SlipDecoder | LengthPrefixDecoder | None = None

    @property
    def encode(self) -> Callable[[bytes], bytes]:
        """How replies are framed on this connection (SLIP until the client's framing is known)."""
        return length_encode if self.framing == "length" else slip_encode

    @property
    def pending(self) -> bool:
        return self._decoder is not None and self._decoder.pending

    @property
    def oversized(self) -> int:
        return 0 if self._decoder is None else self._decoder.oversized

    def feed(self, chunk: bytes) -> list[bytes]:
        """Add received bytes; return the complete frames (possibly none)."""
        if self._decoder is None:
            if not chunk:
                return []
            if chunk[0] in (_END, ord("/"), ord("#")):
                self.framing, self._decoder = "slip", SlipDecoder(self.max_frame)
            else:
                self.framing, self._decoder = "length", LengthPrefixDecoder(self.max_frame)
        return self._decoder.feed(chunk)


# ---------------------------------------------------------------------- UDP
class UdpTransport:
    """UDP server socket with a receive thread and a delivery thread.

    The receive thread runs the compiled loop (:mod:`vibsynth.control.osc._fast`), which never
    waits for the GIL: a busy interpreter cannot make the kernel drop datagrams. What the loop
    queues for Python reaches ``on_batch`` on the delivery thread (normally scheduled), in
    arrival order.

    Parameters
    ----------
    host, port : str, int
        Bind address (port 0 picks a free port; see :attr:`port` after :meth:`open`).
    on_batch : callable
        ``on_batch([(data, peer), ...])``, called on the delivery thread.
    allow : AllowList or None
        Client addresses accepted (None = all); see :func:`parse_allow_list`.
    reply_port : int or None
        Send replies to this port on the sender's host instead of the sender's port.
    rcvbuf : int
        Requested receive buffer size in bytes (the kernel may cap it; see :attr:`rcvbuf`).
    receiver_factory : callable, optional
        ``factory(fd, on_datagrams, allow) -> receiver`` building the compiled receive loop
        (:func:`vibsynth.control.osc.fast.make_receiver`; the OSC server passes one with the
        fast path on). Default: the loop without a fast path.
    priority : int
        SCHED_FIFO priority of the receive loop (:data:`RECEIVE_PRIORITY`; 0 = normal
        scheduling). Where the system refuses it the loop runs normally scheduled; after
        :meth:`start`, :attr:`realtime` says which.
    """

    def __init__(
        self,
        host: str,
        port: int,
        on_batch: BatchHandler,
        *,
        allow: AllowList | None = None,
        reply_port: int | None = None,
        rcvbuf: int = DEFAULT_RCVBUF,
        stats: TransportStats | None = None,
        receiver_factory: ReceiverFactory | None = None,
        priority: int = RECEIVE_PRIORITY,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.on_batch = on_batch
        self.allow = allow
        self.reply_port = reply_port
        self.priority = int(priority)
        self.realtime = False  # the receive loop runs under SCHED_FIFO (known after start())
        self._scheduled = threading.Event()
        self.requested_rcvbuf = rcvbuf
        self.rcvbuf = 0
        self.stats = stats or TransportStats()
        self.receiver_factory = receiver_factory or make_receiver
        self._receiver: Any = None
        self.sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._delivery: threading.Thread | None = None
        self._stop = threading.Event()

    def open(self) -> None:
        """Create and bind the socket (raises OSError, e.g. when the port is taken)."""
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
                if option is None:
                    continue
                try:
                    sock.setsockopt(socket.SOL_SOCKET, option, self.requested_rcvbuf)
                    break
                except OSError:
                    continue
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1024 * 1024)
            sock.bind((self.host, self.port))
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        self.rcvbuf = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self.port = sock.getsockname()[1]
        self.sock = sock

    def start(self) -> None:
        """Open (if needed) and start the receive and delivery threads."""
        if self.sock is None:
            self.open()
        self._stop.clear()
        assert self.sock is not None
        self._receiver = self.receiver_factory(self.sock.fileno(), self._on_datagrams, self.allow)
        self._scheduled.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-udp", daemon=True)
        self._delivery = threading.Thread(target=self._deliver, name="vibsynth-osc-deliver", daemon=True)
        self._thread.start()
        self._delivery.start()
        self._scheduled.wait(2.0)  # so that :attr:`realtime` is known when start() returns

    def stop(self) -> None:
        """Stop the receive thread (within 0.1 s), hand over what it queued, close the socket."""
        self._stop.set()
        if self._receiver is not None:
            self._receiver.stop()
        for thread in (self._thread, self._delivery):
            if thread is not None:
                thread.join(timeout=2.0)
        self._thread = self._delivery = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def send_to(self, data: bytes, address: tuple[str, int]) -> bool:
        """Send one datagram; failures are counted, never raised."""
        sock = self.sock
        if sock is None:
            return False
        try:
            sock.sendto(data, address)
            self.stats.replies += 1
            return True
        except OSError:
            self.stats.send_errors += 1
            return False

    def _run(self) -> None:
        sock = self.sock
        assert sock is not None
        receiver = self._receiver
        self.realtime = _realtime(self.priority)
        self._scheduled.set()
        if receiver is not None:
            try:
                receiver.run()  # the compiled loop; returns after stop()
            except OSError as exc:  # the socket itself failed (not one bad datagram): say so once, count it
                self.stats.receive_failed += 1
                log.error("OSC: the UDP receive loop on port %s stopped: %s", self.port, exc)

    def _deliver(self) -> None:
        """What the receive loop queued for Python, to :attr:`on_batch`, until the loop has ended."""
        receiver = self._receiver
        if receiver is not None:
            while receiver.deliver(_POLL_S):
                pass

    def counters(self) -> dict[str, int]:
        """The receive loop's counters: packets, bytes, fast (handled in C), slow, denied, ..."""
        receiver = self._receiver
        return receiver.counters() if receiver is not None else {}

    def _on_datagrams(self, items: list[tuple[bytes, tuple[str, int]]]) -> None:
        """Datagrams the compiled loop hands to Python (in arrival order), on the delivery thread."""
        batch = []
        for data, address in items:
            reply_to = address if self.reply_port is None else (address[0], self.reply_port)
            batch.append((data, UdpPeer(address, reply_to, self)))
        try:
            self.on_batch(batch)
        except Exception:  # the delivery thread must survive anything
            self.stats.handler_errors += 1
            log.exception("OSC: handler failed on a batch of %d packet(s)", len(batch))


# ---------------------------------------------------------------------- TCP
class _Connection:
    """One TCP connection: its peer, its framing decoder and the time of its last complete packet."""

    __slots__ = ("peer", "decoder", "last_packet")

    def __init__(self, peer: TcpPeer, decoder: FramingDetector, now: float) -> None:
        self.peer = peer
        self.decoder = decoder
        self.last_packet = now


class TcpTransport:
    """TCP listener with SLIP-framed OSC packets; one selector thread serves every connection.

    Stalled clients cannot lock others out: a new connection is refused (closed at
    once, counted in ``tcp_refused``) when its address already holds ``max_per_peer``
    connections or ``max_connections`` are open, and a connection that delivered no
    complete packet for ``idle_timeout_s`` is closed (``tcp_idle_closed``). A
    ``/notify`` subscriber (``peer.keep_alive``) may stay silent as long as it likes,
    but not in the middle of a frame.

    Parameters
    ----------
    host, port : str, int
        Bind address (port 0 picks a free port).
    on_batch : callable
        ``on_batch([(frame, peer), ...])``, called on the selector thread.
    allow : AllowList or None
        Client addresses accepted (None = all).
    max_connections : int
        Open connections in all (:data:`TCP_MAX_CONNECTIONS`).
    max_per_peer : int
        Open connections from one client IP address (:data:`TCP_MAX_PER_PEER`).
    idle_timeout_s : float
        Seconds without a complete packet before a connection is closed (:data:`TCP_IDLE_TIMEOUT_S`).
    stats : TransportStats, optional
    on_close : callable, optional
        Called with the peer of every closed connection.
    clock : callable
        Monotonic clock in seconds (injectable for tests).
    """

    def __init__(
        self,
        host: str,
        port: int,
        on_batch: BatchHandler,
        *,
        allow: AllowList | None = None,
        max_connections: int = TCP_MAX_CONNECTIONS,
        max_per_peer: int = TCP_MAX_PER_PEER,
        idle_timeout_s: float = TCP_IDLE_TIMEOUT_S,
        stats: TransportStats | None = None,
        on_close: Callable[[TcpPeer], object] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.on_batch = on_batch
        self.on_close = on_close
        self.allow = allow
        self.max_connections = int(max_connections)
        self.max_per_peer = int(max_per_peer)
        self.idle_timeout_s = float(idle_timeout_s)
        self.clock = clock
        self.stats = stats or TransportStats()
        self.sock: socket.socket | None = None
        self._selector: selectors.DefaultSelector | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._peers: dict[socket.socket, _Connection] = {}

    def open(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(64)
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        self.port = sock.getsockname()[1]
        self.sock = sock

    def start(self) -> None:
        if self.sock is None:
            self.open()
        assert self.sock is not None
        self._selector = selectors.DefaultSelector()
        self._selector.register(self.sock, selectors.EVENT_READ)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-tcp", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for conn in list(self._peers):
            self._drop(conn)
        if self._selector is not None:
            self._selector.close()
            self._selector = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    @property
    def connections(self) -> int:
        """Open connections."""
        return len(self._peers)

    def _drop(self, conn: socket.socket) -> None:
        entry = self._peers.pop(conn, None)
        try:
            if self._selector is not None:
                self._selector.unregister(conn)
        except (KeyError, ValueError):
            pass
        conn.close()
        if entry is not None:
            entry.peer.closed = True
            if self.on_close is not None:
                self.on_close(entry.peer)

    def _refusal(self, ip: str) -> str | None:
        """Why a new connection from ``ip`` is refused (None = accepted)."""
        if self.allow is not None and ip not in self.allow:
            return "not in osc.allow"
        if len(self._peers) >= self.max_connections:
            return f"{self.max_connections} connections open (the limit)"
        if sum(1 for c in self._peers.values() if c.peer.address[0] == ip) >= self.max_per_peer:
            return f"{self.max_per_peer} connections open from this address (the limit per client)"
        return None

    def _accept(self) -> None:
        assert self.sock is not None and self._selector is not None
        try:
            conn, address = self.sock.accept()
        except OSError:
            return
        reason = self._refusal(address[0])
        if reason is not None:
            if reason.startswith("not in"):
                self.stats.denied += 1
            else:
                self.stats.tcp_refused += 1
            log.debug("OSC: refused a TCP connection from %s: %s", address[0], reason)
            conn.close()
            return
        conn.setblocking(False)
        self.stats.tcp_connections += 1
        self._peers[conn] = _Connection(TcpPeer(conn, address[:2], self.stats), FramingDetector(), self.clock())
        self._selector.register(conn, selectors.EVENT_READ)

    def _expire_idle(self) -> None:
        """Close connections without a complete packet for ``idle_timeout_s``."""
        now = self.clock()
        for conn, entry in list(self._peers.items()):
            if now - entry.last_packet < self.idle_timeout_s:
                continue
            if entry.peer.keep_alive and not entry.decoder.pending:
                continue
            self.stats.tcp_idle_closed += 1
            log.debug(
                "OSC: closed the TCP connection of %s (no complete packet for %.0f s)",
                entry.peer.address[0],
                now - entry.last_packet,
            )
            self._drop(conn)

    def _receive(self, conn: socket.socket) -> None:
        """Read what a connection sent and hand its complete frames to the handler."""
        try:
            chunk = conn.recv(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._drop(conn)
            return
        entry = self._peers[conn]
        peer, decoder = entry.peer, entry.decoder
        before = decoder.oversized
        frames = decoder.feed(chunk)
        peer.encode = decoder.encode
        self.stats.oversized_frames += decoder.oversized - before
        for frame in frames:
            self.stats.packets += 1
            self.stats.bytes += len(frame)
        if frames:
            entry.last_packet = self.clock()
            try:
                self.on_batch([(frame, peer) for frame in frames])
            except Exception:
                self.stats.handler_errors += 1
                log.exception("OSC: handler failed on TCP frames from %s", peer.address[0])
        if peer.closed:
            self._drop(conn)

    def _run(self) -> None:
        assert self._selector is not None
        while not self._stop.is_set():
            for key, _ in self._selector.select(timeout=_POLL_S):
                if key.fileobj is self.sock:
                    self._accept()
                elif key.fileobj in self._peers:
                    assert isinstance(key.fileobj, socket.socket)
                    self._receive(key.fileobj)
            self._expire_idle()
