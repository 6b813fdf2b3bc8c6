"""The OSC server: a handler behind its transports, with the notify and sync workers."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from functools import partial

from vibsynth.control.controller import Controller
from vibsynth.control.osc.address import normalize_prefix
from vibsynth.control.osc.fast import make_receiver
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.monitor import MonitorWorker
from vibsynth.control.osc.replies import _LOOPBACK
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.osc.tables import register_tables
from vibsynth.control.osc.transport import (
    DEFAULT_RCVBUF,
    RECEIVE_PRIORITY,
    TCP_IDLE_TIMEOUT_S,
    TCP_MAX_CONNECTIONS,
    TCP_MAX_PER_PEER,
    TcpTransport,
    TransportStats,
    UdpTransport,
)
from vibsynth.control.osc.workers import Notifier, PeerLike, SyncWorker
from vibsynth.errors import ConfigError
from vibsynth.settings.allow_list import resolve_allow_list

log = logging.getLogger(__name__)


class OscServer:
    """The OSC control server: transports + handler + workers (the adapter's ControlServer).

    Parameters
    ----------
    controller : Controller
    host, port : str, int
    prefix, allow, reply_port, schedule_horizon_s, notify_rate_hz, tcp, speed_curve
        See the ``osc:`` config section and docs/osc.md.
    receive_priority : int
        SCHED_FIFO priority of the UDP receive loop (0 = normally scheduled; ``osc.receive_priority``).
    tcp_max_connections, tcp_max_per_peer, tcp_idle_timeout_s
        TCP connection limits (see :class:`~vibsynth.control.osc.transport.TcpTransport`).
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
        receive_priority: int = RECEIVE_PRIORITY,
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
        self.tap = controller.tap  # shared with the MIDI input: one stream for monitors and status
        self.monitor = MonitorWorker(self.tap, prefix)
        self.sync_worker = SyncWorker(controller, self._reply_synced, timeout_s=schedule_horizon_s + 2.0)
        self.handler = OscHandler(
            controller,
            prefix=prefix,
            speed_curve=speed_curve,
            schedule_horizon_s=schedule_horizon_s,
            notifier=self.notifier,
            sync_worker=self.sync_worker,
            block_size=block_size,
            extra_status=self._status_extras,
            tap=self.tap,
            monitor=self.monitor,
        )
        register_tables(self.handler)
        self.udp = UdpTransport(
            host,
            port,
            self.handler.handle_batch,
            allow=allow_set,
            reply_port=reply_port,
            rcvbuf=rcvbuf,
            stats=self.stats,
            priority=receive_priority,
            receiver_factory=partial(make_receiver, controller=controller, space=self.handler.space, tap=self.tap),
        )
        self.tcp = (
            TcpTransport(
                host,
                port,
                self.handler.handle_batch,
                allow=allow_set,
                stats=self.stats,
                on_close=self._closed,
                max_connections=tcp_max_connections,
                max_per_peer=tcp_max_per_peer,
                idle_timeout_s=tcp_idle_timeout_s,
            )
            if tcp
            else None
        )
        self._started = False
        self._bound = False

    def _closed(self, peer: PeerLike) -> None:
        """A TCP connection closed: end its subscriptions."""
        self.notifier.unsubscribe(peer)
        self.monitor.unsubscribe(peer)

    def _reply_synced(self, peer: PeerLike, sync_id: int, ok: bool) -> None:
        self.handler.reply_synced(peer, sync_id, ok)

    def _status_extras(self) -> list[tuple[str, object]]:
        s = self.stats
        return self._transport_status() + [
            ("tcp_refused", s.tcp_refused),
            ("tcp_idle_closed", s.tcp_idle_closed),
            ("receive_failed", s.receive_failed),
            ("queue_full", self.udp.counters().get("queue_full", 0)),
        ]

    def counters(self) -> dict[str, int]:
        """Transport counters of both transports: the TCP ones in :attr:`stats`, the UDP ones in
        the compiled receive loop (``fast_path``: messages it handled without Python)."""
        s, udp = self.stats, self.udp.counters()
        return {
            "packets": s.packets + udp.get("packets", 0),
            "bytes": s.bytes + udp.get("bytes", 0),
            "denied": s.denied + udp.get("denied", 0),
            "fast_path": udp.get("fast", 0),
            "replies": s.replies,
            "send_errors": s.send_errors,
        }

    def _transport_status(self) -> list[tuple[str, object]]:
        c = self.counters()
        return [
            ("packets", c["packets"]),
            ("denied", c["denied"]),
            ("fast_path", c["fast_path"]),
            ("replies", c["replies"]),
            ("send_errors", c["send_errors"]),
            ("rcvbuf", self.udp.rcvbuf),
        ]

    @property
    def port(self) -> int:
        """The bound UDP port (useful with port 0)."""
        return self.udp.port

    def bind(self) -> None:
        """Bind the sockets: the port is known (HOST_INFO, the banner) and datagrams wait in the
        kernel's receive buffer until :meth:`start` answers them. ``serve`` binds first and starts
        last, so a client's first ``/status`` already sees every part of the service.

        Raises
        ------
        ConfigError
            If the address cannot be bound (e.g. port in use).
        """
        if self._bound:
            return
        try:
            self.udp.open()
            if self.tcp is not None:
                self.tcp.port = self.udp.port
                self.tcp.open()
        except OSError as exc:
            self.udp.stop()
            raise ConfigError(
                f"OSC: cannot listen on {self.udp.host}:{self.udp.port}: {exc.strerror or exc} "
                "(set osc.port or --osc-port)"
            ) from None
        self._bound = True

    def start(self) -> None:
        """Bind the sockets (unless :meth:`bind` did) and start the receive, notify and sync threads.

        Raises
        ------
        ConfigError
            If the address cannot be bound (e.g. port in use).
        """
        self.bind()
        self.notifier.start()
        self.monitor.start()
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
        self.monitor.stop()
        self.sync_worker.stop()
        self.handler.close()
        self._started = self._bound = False

    def describe(self) -> str:
        """One line for the start-up banner."""
        host = self.udp.host
        text = f"OSC on udp://{host}:{self.udp.port}{self.handler.prefix or '/'}"
        if self.tcp is not None:
            text += f" and tcp://{host}:{self.udp.port} (SLIP or length-prefixed)"
        if self.udp.rcvbuf:
            text += f", receive buffer {self.udp.rcvbuf // 1024} KiB"
        if self.udp.realtime:
            text += f", real-time receive thread (SCHED_FIFO {self.udp.priority})"
        if host not in _LOOPBACK:
            text += ", reachable from the network" + (" (allow-list)" if self.udp.allow else "")
        return text
