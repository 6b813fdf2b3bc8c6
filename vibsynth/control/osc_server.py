"""OSC transports: UDP (one receive thread, large receive buffer) and optional TCP with SLIP framing.

Transports know nothing of OSC addresses: they receive packets, drop those from
clients outside the allow-list (counted), and hand batches of ``(data, peer)`` to a
callback on their single receive thread: after waiting for the first packet, the UDP
thread drains whatever else is already queued in the socket (up to
:data:`MAX_BATCH`), so the handler can coalesce moves that arrived together. ``peer.send(data)`` replies to the sender (UDP:
its address, or the configured reply port on its host; TCP: the same connection).
"""
from __future__ import annotations

import errno
import logging
import select
import selectors
import socket
import threading
from dataclasses import dataclass, field
from typing import Callable, Iterable

from vibsynth.errors import ConfigError

__all__ = [
    "TransportStats",
    "UdpPeer",
    "TcpPeer",
    "UdpTransport",
    "TcpSlipTransport",
    "slip_encode",
    "SlipDecoder",
    "resolve_allow_list",
    "DEFAULT_RCVBUF",
]

log = logging.getLogger(__name__)

DEFAULT_RCVBUF = 4 * 1024 * 1024
MAX_DATAGRAM = 65536
_POLL_S = 0.25

MAX_BATCH = 256

BatchHandler = Callable[[list], None]
"""``handler([(data, peer), ...])``, called on the receive thread."""


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


@dataclass(frozen=True, slots=True)
class UdpPeer:
    """A UDP client: replies go to ``reply_to`` through the server socket."""

    address: tuple[str, int]
    reply_to: tuple[str, int]
    transport: "UdpTransport" = field(compare=False, hash=False, repr=False)

    @property
    def key(self) -> tuple:
        return ("udp", self.reply_to)

    def send(self, data: bytes) -> bool:
        return self.transport.send_to(data, self.reply_to)


class TcpPeer:
    """A TCP client connection: replies are SLIP frames on the same connection."""

    def __init__(self, sock: socket.socket, address: tuple[str, int], stats: TransportStats) -> None:
        self.sock = sock
        self.address = address
        self.closed = False
        self._stats = stats
        self._lock = threading.Lock()

    @property
    def key(self) -> tuple:
        return ("tcp", self.address)

    def send(self, data: bytes) -> bool:
        """Queue a SLIP frame on the (non-blocking) connection; a client that stopped reading is dropped."""
        if self.closed:
            return False
        frame = slip_encode(data)
        try:
            with self._lock:
                self.sock.sendall(frame)
            self._stats.replies += 1
            return True
        except OSError:  # BlockingIOError: its buffer is full (possibly mid-frame): drop it
            self._stats.send_errors += 1
            self.closed = True
            return False


def resolve_allow_list(entries: Iterable[str] | None) -> frozenset[str] | None:
    """Resolve configured client addresses/host names to a set of IP strings (None = allow all).

    Raises
    ------
    ConfigError
        If a name cannot be resolved.
    """
    entries = list(entries or [])
    if not entries:
        return None
    allowed = set()
    for entry in entries:
        try:
            for info in socket.getaddrinfo(str(entry), None):
                allowed.add(info[4][0])
        except OSError as exc:
            raise ConfigError(f"osc.allow: cannot resolve {entry!r}: {exc}") from None
    return frozenset(allowed)


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


# ---------------------------------------------------------------------- UDP
class UdpTransport:
    """UDP server socket with one receive thread.

    Parameters
    ----------
    host, port : str, int
        Bind address (port 0 picks a free port; see :attr:`port` after :meth:`open`).
    on_batch : callable
        ``on_batch([(data, peer), ...])``, called on the receive thread.
    allow : frozenset of str or None
        Client IPs accepted (None = all).
    reply_port : int or None
        Send replies to this port on the sender's host instead of the sender's port.
    rcvbuf : int
        Requested receive buffer size in bytes (the kernel may cap it; see :attr:`rcvbuf`).
    """

    def __init__(
        self,
        host: str,
        port: int,
        on_batch: BatchHandler,
        *,
        allow: frozenset[str] | None = None,
        reply_port: int | None = None,
        rcvbuf: int = DEFAULT_RCVBUF,
        stats: TransportStats | None = None,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.on_batch = on_batch
        self.allow = allow
        self.reply_port = reply_port
        self.requested_rcvbuf = rcvbuf
        self.rcvbuf = 0
        self.stats = stats or TransportStats()
        self.sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
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
        """Open (if needed) and start the receive thread."""
        if self.sock is None:
            self.open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-udp", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the receive thread and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
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
        stats = self.stats
        allow = self.allow
        poller = select.poll()
        poller.register(sock, select.POLLIN)
        while not self._stop.is_set():
            if not poller.poll(_POLL_S * 1000):
                continue
            batch = []
            while len(batch) < MAX_BATCH:
                try:
                    data, address = sock.recvfrom(MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError as exc:
                    if self._stop.is_set() or exc.errno == errno.EBADF:
                        return
                    stats.send_errors += 1  # e.g. ECONNREFUSED reported for an earlier reply
                    continue
                stats.packets += 1
                stats.bytes += len(data)
                if allow is not None and address[0] not in allow:
                    stats.denied += 1
                    log.debug("OSC: dropped a packet from %s (not in osc.allow)", address[0])
                    continue
                reply_to = address[:2] if self.reply_port is None else (address[0], self.reply_port)
                batch.append((data, UdpPeer(address[:2], reply_to, self)))
            if not batch:
                continue
            try:
                self.on_batch(batch)
            except Exception:  # the receive thread must survive anything
                stats.handler_errors += 1
                log.exception("OSC: handler failed on a batch of %d packet(s)", len(batch))


# ---------------------------------------------------------------------- TCP
class TcpSlipTransport:
    """TCP listener with SLIP-framed OSC packets; one selector thread serves every connection."""

    def __init__(
        self,
        host: str,
        port: int,
        on_batch: BatchHandler,
        *,
        allow: frozenset[str] | None = None,
        max_connections: int = 16,
        stats: TransportStats | None = None,
        on_close: Callable[[TcpPeer], None] | None = None,
    ) -> None:
        self.host = host
        self.port = int(port)
        self.on_batch = on_batch
        self.on_close = on_close
        self.allow = allow
        self.max_connections = max_connections
        self.stats = stats or TransportStats()
        self.sock: socket.socket | None = None
        self._selector: selectors.DefaultSelector | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._peers: dict[socket.socket, tuple[TcpPeer, SlipDecoder]] = {}

    def open(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(8)
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

    def _drop(self, conn: socket.socket) -> None:
        peer, _ = self._peers.pop(conn, (None, None))
        try:
            if self._selector is not None:
                self._selector.unregister(conn)
        except (KeyError, ValueError):
            pass
        conn.close()
        if peer is not None:
            peer.closed = True
            if self.on_close is not None:
                self.on_close(peer)

    def _accept(self) -> None:
        assert self.sock is not None and self._selector is not None
        try:
            conn, address = self.sock.accept()
        except OSError:
            return
        if (self.allow is not None and address[0] not in self.allow) or len(self._peers) >= self.max_connections:
            self.stats.denied += 1
            conn.close()
            return
        conn.setblocking(False)
        self.stats.tcp_connections += 1
        self._peers[conn] = (TcpPeer(conn, address[:2], self.stats), SlipDecoder())
        self._selector.register(conn, selectors.EVENT_READ)

    def _run(self) -> None:
        assert self._selector is not None
        while not self._stop.is_set():
            for key, _ in self._selector.select(timeout=_POLL_S):
                if key.fileobj is self.sock:
                    self._accept()
                    continue
                conn = key.fileobj
                assert isinstance(conn, socket.socket)
                try:
                    chunk = conn.recv(MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:
                    chunk = b""
                if not chunk:
                    self._drop(conn)
                    continue
                peer, decoder = self._peers[conn]
                before = decoder.oversized
                frames = decoder.feed(chunk)
                self.stats.oversized_frames += decoder.oversized - before
                for frame in frames:
                    self.stats.packets += 1
                    self.stats.bytes += len(frame)
                if frames:
                    try:
                        self.on_batch([(frame, peer) for frame in frames])
                    except Exception:
                        self.stats.handler_errors += 1
                        log.exception("OSC: handler failed on TCP frames from %s", peer.address[0])
                if peer.closed:
                    self._drop(conn)
