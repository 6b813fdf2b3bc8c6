"""The OSCQuery server: the tree over HTTP (JSON) and a WebSocket on the same port (aiohttp, own loop thread).

HTTP (Vidvox OSCQueryProposal): ``GET /`` the whole tree, ``GET /vibsynth/ch/1`` a node,
``?VALUE`` ``?TYPE`` ``?RANGE`` ``?ACCESS`` ``?DESCRIPTION`` ``?UNIT`` ``?FULL_PATH``
``?CONTENTS`` one attribute, ``?HOST_INFO`` the server. An attribute the node does not have
(VALUE of a trigger) is 204, an unknown attribute or more than one 400, an unknown path 404.

WebSocket (``ws://HOST:PORT/``): JSON text ``{"COMMAND": "LISTEN"|"IGNORE", "DATA": path}``;
after LISTEN the path's value is sent at once and at every change, from any side (OSC, MIDI,
the studio, follow, clips: the controller's knob events; other values are polled every
:data:`POLL_S` while listened to), as a binary OSC message, newest value per path (coalesced,
at most one per path per :data:`PUSH_INTERVAL_S`). Structure changes (a preset added on disk
changes the preset nodes' VALS; follow or a clip player starting adds nodes) are
``PATH_CHANGED`` / ``PATH_ADDED`` / ``PATH_REMOVED`` JSON. Binary frames from a client are OSC
packets handed to the OSC handler, after the OSC server's allow-list (``osc.allow``), exactly
as a UDP datagram; its replies come back on the socket.

Security (as the studio's gate, :mod:`~vibsynth.control.studio.security`): reads need no
token (the tools that read OSCQuery send none); the ``Host`` header must name an IP address,
``localhost`` or the advertised ``.local`` name with our port (a DNS-rebinding page's name is
refused); a WebSocket with a foreign ``Origin`` is refused, and one that breaks RFC 6455's framing
(a client frame without a mask, reserved bits, an oversized or fragmented control frame) is closed
with 1002 (:mod:`~vibsynth.control.websocket`); URLs, path depth, messages,
listens, clients and rates are bounded. Every refusal is one clear answer, counted by reason
(:meth:`OscQueryServer.refused`, ``/status``).
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from aiohttp import WSCloseCode, WSMsgType, web

from vibsynth.control.controller import Controller, KnobEvent
from vibsynth.control.loop_server import LoopServer
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.oscquery.tree import ATTRIBUTES, Tree
from vibsynth.control.studio.commands import Throttle
from vibsynth.control.websocket import StrictWebSocketResponse, UnmaskedFrame, accept
from vibsynth.errors import VibsynthError

__all__ = [
    "OscQueryServer",
    "MAX_CLIENTS",
    "MAX_LISTENS",
    "MAX_URL",
    "MAX_DEPTH",
    "MAX_MESSAGE_BYTES",
    "PUSH_INTERVAL_S",
    "POLL_S",
    "EXTENSIONS",
]

log = logging.getLogger(__name__)

#: Most WebSocket clients at once (each costs a socket and a sender task).
MAX_CLIENTS = 128
#: Most paths one client listens to.
MAX_LISTENS = 256
#: Longest request target (path and query), characters.
MAX_URL = 1024
#: Most path parts (the deepest node has 4: /vibsynth/source/16/pos).
MAX_DEPTH = 16
#: Largest WebSocket message (a JSON command or an OSC packet), bytes.
MAX_MESSAGE_BYTES = 16384
#: Values of one path are pushed at most this often (newer ones replace waiting ones).
PUSH_INTERVAL_S = 0.005
#: Listened values without change events (sources, follow) are read this often.
POLL_S = 0.05
#: The tree's structure (preset and clip names, running parts) is compared this often while WebSocket
#: clients are connected (otherwise when a request reads it, at most this often).
REFRESH_S = 1.0
#: JSON commands (LISTEN, IGNORE) and OSC packets one client may send per second (burst the same).
CLIENT_RATE = 1000.0
#: HTTP requests per second to the whole server (burst the same); more are answered 503.
HTTP_RATE = 500.0
#: Error answers per second to one client (more are counted, not sent).
ERROR_RATE = 20.0
#: Messages waiting for one client besides the values (replies, structure changes); more are dropped.
MAX_QUEUED = 256

#: HOST_INFO EXTENSIONS: true for what this server does.
EXTENSIONS = {
    "ACCESS": True,
    "VALUE": True,
    "RANGE": True,
    "DESCRIPTION": True,
    "TYPE": True,
    "UNIT": True,
    "LISTEN": True,
    "PATH_CHANGED": True,
    "PATH_ADDED": True,
    "PATH_REMOVED": True,
    "PATH_RENAMED": False,
    "TAGS": False,
    "EXTENDED_TYPE": False,
    "CLIPMODE": False,
    "CRITICAL": False,
    "OVERLOADS": False,
    "HTML": False,
}

_WILDCARD = ("0.0.0.0", "", "::")


def _host_name_ok(name: str, local_names: frozenset[str]) -> bool:
    """An IP address, localhost or our advertised name: never a name a rebinding page controls."""
    name = name.strip("[]").lower().rstrip(".")
    if name == "localhost" or name in local_names:
        return True
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


@dataclass(eq=False)
class _Client:
    """One WebSocket client: what it listens to and what waits to be sent."""

    ws: web.WebSocketResponse
    ident: int
    remote: str
    listens: set[str] = field(default_factory=set)
    values: dict[str, bytes] = field(default_factory=dict)  # path -> newest value message
    queued: deque[str | bytes] = field(default_factory=deque)  # replies (bytes), JSON texts (str)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    throttle: Throttle = field(default_factory=lambda: Throttle(rate=CLIENT_RATE, burst=CLIENT_RATE))
    errors: Throttle = field(default_factory=lambda: Throttle(rate=ERROR_RATE, burst=ERROR_RATE))
    sent: int = 0
    dropped: int = 0


class _WsPeer:
    """A WebSocket client as an OSC reply destination (:class:`~vibsynth.control.osc.workers.PeerLike`)."""

    datagram = False

    def __init__(self, server: OscQueryServer, client: _Client) -> None:
        self.server = server
        self.client = client
        self.address = (client.remote, 0)

    @property
    def key(self) -> tuple:
        return ("oscquery-ws", self.client.ident)

    def send(self, data: bytes) -> bool:
        """Queue a reply (on the loop) or a push (``/notify``, ``/monitor``: from their worker threads)."""
        if threading.current_thread() is self.server._thread:
            return self.server._enqueue(self.client, data)
        if self.client.ws.closed:
            return False
        self.server.call_in_loop(lambda: self.server._enqueue(self.client, data))
        return True


class OscQueryServer(LoopServer):
    """The OSCQuery server (a ControlServer: ``start``, ``stop``, ``describe``).

    Parameters
    ----------
    tree : Tree
    handler : OscHandler
        Takes the OSC packets clients send over the WebSocket.
    controller : Controller
        Its knob events are pushed to listeners.
    host, port : str, int
        Where to listen (port 0 = any free port).
    osc_host, osc_port : str, int
        The OSC server (HOST_INFO's OSC_IP and OSC_PORT).
    allow : AllowList or None
        The OSC server's allow-list (``osc.allow``), for OSC packets over the WebSocket.
    name : str
        HOST_INFO's NAME.
    local_names : iterable of str
        Host names besides IP addresses and localhost the Host header may carry (the
        advertised ``NAME.local``).
    port_fallback : bool
        When the port is taken, listen on a free one (with a warning) instead of failing.
    """

    name = "oscquery"
    title = "OSCQuery"
    bind_hint = "(set discovery.oscquery_port or --oscquery-port, or --no-discovery)"

    def __init__(
        self,
        tree: Tree,
        handler: OscHandler,
        controller: Controller,
        *,
        host: str = "127.0.0.1",
        port: int = 9572,
        osc_host: str = "127.0.0.1",
        osc_port: int = 9570,
        allow: Any = None,
        name: str = "vibsynth",
        local_names: tuple[str, ...] = (),
        port_fallback: bool = False,
    ) -> None:
        super().__init__(host, port, port_fallback=port_fallback)
        self.tree = tree
        self.handler = handler
        self.controller = controller
        self.osc_host = osc_host
        self.osc_port = int(osc_port)
        self.allow = allow
        self.service_name = name
        self.local_names = frozenset(n.lower().rstrip(".") for n in local_names)
        self.clients: set[_Client] = set()
        self._listeners: dict[str, set[_Client]] = {}
        self._lock = threading.Lock()
        self._refused: Counter[str] = Counter()
        self._dirty: set[str] = set()
        self._scheduled = False
        self._next_id = 0
        self._http = Throttle(rate=HTTP_RATE, burst=HTTP_RATE)
        self._rebuilt_at = time.monotonic()
        self._tasks: list[asyncio.Task[None]] = []
        self._unsubscribe: Callable[[], None] | None = None
        self._last_polled: dict[str, bytes] = {}
        self.pushed = 0
        self.structure_events = 0

    # ------------------------------------------------------------------ counters
    def count(self, reason: str) -> None:
        """Count a refusal (any thread)."""
        with self._lock:
            self._refused[reason] += 1
        self.controller.count_error(f"oscquery.{reason}")

    def refused(self) -> dict[str, int]:
        """Refusals so far by reason (host, origin, too_large, too_deep, bad_query, malformed, unmasked, flood,
        listens, clients, not_allowed, unknown_path, queue_full)."""
        with self._lock:
            return dict(self._refused)

    def status_pairs(self) -> list[tuple[str, object]]:
        """``(key, value)`` pairs for status: clients, listens, pushes, refusals."""
        refused = self.refused()
        return [
            ("oscquery_clients", len(self.clients)),
            ("oscquery_listens", sum(len(c.listens) for c in list(self.clients))),
            ("oscquery_pushed", self.pushed),
            ("oscquery_refused", sum(refused.values())),
        ]

    # ------------------------------------------------------------------ life cycle
    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in _WILDCARD else self.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/"

    def describe(self) -> str:
        text = f"OSCQuery on {self.url} (WebSocket on the same port)"
        if self.port != self.requested_port and self.requested_port != 0:
            text += f" (port {self.requested_port} was in use)"
        return text

    def start(self) -> None:
        """Bind and start the loop thread.

        Raises
        ------
        ConfigError
            The address cannot be bound.
        """
        self.start_loop("vibsynth-oscquery")
        self._unsubscribe = self.controller.subscribe(self._on_knob_event)
        log.info("%s", self.describe())

    def stop(self) -> None:
        """Close the clients and stop the loop (idempotent)."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        self.stop_loop()

    async def _make_app(self) -> web.Application:
        app = web.Application(client_max_size=MAX_MESSAGE_BYTES)
        app.router.add_route("*", "/{tail:.*}", self._request)
        return app

    async def _bound(self) -> None:
        self._tasks = [asyncio.ensure_future(self._poll()), asyncio.ensure_future(self._refresh())]

    async def _closing(self) -> None:
        for task in self._tasks:
            task.cancel()
        for client in list(self.clients):
            await client.ws.close(code=WSCloseCode.GOING_AWAY, message=b"vibsynth is stopping")

    # ------------------------------------------------------------------ HTTP
    def _refuse(self, reason: str, status: int, text: str) -> web.Response:
        self.count(reason)
        return web.Response(status=status, text=text + "\n", headers={"Cache-Control": "no-store"})

    def host_ok(self, host: str | None) -> bool:
        """The Host header names an IP address, localhost or our ``.local`` name, with our port."""
        if not host:
            return False
        name, sep, port = host.rpartition(":")
        if not sep or not port.isdigit() or int(port) != self.port:
            return False
        if ":" in name and not (name.startswith("[") and name.endswith("]")):
            return False
        return _host_name_ok(name, self.local_names)

    async def _request(self, request: web.Request) -> web.StreamResponse:
        if not self.host_ok(request.host):
            return self._refuse("host", 403, "forbidden: unexpected Host header (use an IP address or localhost)")
        if len(request.raw_path) > MAX_URL:
            return self._refuse("too_large", 414, f"request target longer than {MAX_URL} characters")
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return await self._websocket(request)
        if request.method not in ("GET", "HEAD"):
            return self._refuse("bad_query", 405, "only GET (and WebSocket) are served")
        if not self._http.take():
            return self._refuse("flood", 503, "too many requests: slow down")
        path = request.path
        if path.count("/") > MAX_DEPTH:
            return self._refuse("too_deep", 400, f"path deeper than {MAX_DEPTH} parts")
        query = request.query_string
        attributes = [a for a in query.split("&") if a] if query else []
        if len(attributes) > 1:
            return self._refuse("bad_query", 400, "one attribute per query (e.g. ?VALUE)")
        attribute = attributes[0].split("=", 1)[0] if attributes else None
        if attribute is not None and attribute not in ATTRIBUTES:
            return self._refuse(
                "bad_query", 400, f"unknown attribute {attribute[:40]!r}; known: {', '.join(ATTRIBUTES)}"
            )
        if attribute == "HOST_INFO":
            return web.json_response(self.host_info(request))
        if time.monotonic() - self._rebuilt_at > REFRESH_S:
            await self._rebuild()  # nobody listening: the structure is compared when it is read
        node = self.tree.find(path)
        if node is None:
            self.count("unknown_path")
            return web.Response(status=404, text=f"no OSC method or container at {path[:200]}\n")
        data = node.json(self.tree.context(), deep=attribute in (None, "CONTENTS"))
        if attribute is None:
            return web.json_response(data)
        if attribute not in data:
            return web.Response(status=204)
        return web.json_response({attribute: data[attribute]})

    def host_info(self, request: web.Request | None = None) -> dict[str, Any]:
        """HOST_INFO: NAME, OSC_IP/PORT/TRANSPORT, WS_IP/PORT, EXTENSIONS."""
        local = None
        if request is not None and request.transport is not None:
            sockname = request.transport.get_extra_info("sockname")
            local = sockname[0] if sockname else None
        osc_ip = local if self.osc_host in _WILDCARD and local else self.osc_host
        ws_ip = local if self.host in _WILDCARD and local else self.host
        return {
            "NAME": self.service_name,
            "OSC_IP": osc_ip,
            "OSC_PORT": self.osc_port,
            "OSC_TRANSPORT": "UDP",
            "WS_IP": ws_ip,
            "WS_PORT": self.port,
            "EXTENSIONS": dict(EXTENSIONS),
        }

    # ------------------------------------------------------------------ WebSocket
    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin != f"http://{request.host}":
            return self._refuse("origin", 403, "forbidden: WebSocket from another origin")
        if len(self.clients) >= MAX_CLIENTS:
            return self._refuse("clients", 503, f"too many OSCQuery clients (max {MAX_CLIENTS})")
        ws = StrictWebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, heartbeat=20.0, compress=False)
        if not await accept(ws, request):  # the client reset during the handshake: nobody to answer
            return web.Response(status=400)
        self._next_id += 1
        client = _Client(ws=ws, ident=self._next_id, remote=request.remote or "")
        self.clients.add(client)
        sender = asyncio.ensure_future(self._sender(client))
        peer = _WsPeer(self, client)
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    self._command(client, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    self._osc(client, peer, msg.data)
                elif msg.type == WSMsgType.ERROR:  # aiohttp has closed it: 1009 too large, 1002 protocol error
                    code = getattr(msg.data, "code", None) or ws.close_code
                    if isinstance(msg.data, UnmaskedFrame):
                        self.count("unmasked")
                    else:
                        self.count("too_large" if code == WSCloseCode.MESSAGE_TOO_BIG else "malformed")
                    break
        finally:
            self.clients.discard(client)
            for subscriptions in (self.handler.notifier, self.handler.monitor):
                if subscriptions is not None:  # a /notify or /monitor sent over this socket ends with it
                    subscriptions.unsubscribe(peer)
            for path in client.listens:
                listeners = self._listeners.get(path)
                if listeners is not None:
                    listeners.discard(client)
                    if not listeners:
                        del self._listeners[path]
            sender.cancel()
        return ws

    def _error(self, client: _Client, reason: str, text: str) -> None:
        """Count a refusal and tell the client (a JSON ``ERROR`` command; rate-limited)."""
        self.count(reason)
        if client.errors.take():
            self._enqueue(client, json.dumps({"COMMAND": "ERROR", "DATA": text}))

    def _command(self, client: _Client, text: str) -> None:
        if not client.throttle.take():
            self._error(client, "flood", "too many messages: slow down")
            return
        try:
            data = json.loads(text)
        except (ValueError, RecursionError):
            self._error(client, "malformed", 'not JSON: send {"COMMAND": "LISTEN", "DATA": "/path"}')
            return
        command = data.get("COMMAND") if isinstance(data, dict) else None
        path = data.get("DATA") if isinstance(data, dict) else None
        if command not in ("LISTEN", "IGNORE") or not isinstance(path, str):
            self._error(client, "malformed", 'expected {"COMMAND": "LISTEN" or "IGNORE", "DATA": "/path"}')
            return
        if command == "IGNORE":
            client.listens.discard(path)
            client.values.pop(path, None)
            listeners = self._listeners.get(path)
            if listeners is not None:
                listeners.discard(client)
                if not listeners:
                    del self._listeners[path]
            return
        if path not in self.tree.methods:
            self._error(client, "unknown_path", f"LISTEN: no OSC method at {path[:200]}")
            return
        if path not in client.listens and len(client.listens) >= MAX_LISTENS:
            self._error(client, "listens", f"LISTEN: at most {MAX_LISTENS} paths per client")
            return
        client.listens.add(path)
        self._listeners.setdefault(path, set()).add(client)
        message = self._value_message(path, self.tree.context())
        if message is not None:
            client.values[path] = message
            client.wake.set()

    def _osc(self, client: _Client, peer: _WsPeer, data: bytes) -> None:
        if self.allow is not None and client.remote not in self.allow:
            self._error(client, "not_allowed", "OSC from this address is not in osc.allow")
            return
        if not client.throttle.take():
            self._error(client, "flood", "too many messages: slow down")
            return
        self.handler.handle_batch([(bytes(data), peer)])

    def _enqueue(self, client: _Client, item: str | bytes) -> bool:
        """Queue a reply or a JSON command for one client (on the loop)."""
        if len(client.queued) >= MAX_QUEUED:
            client.dropped += 1
            self.count("queue_full")
            return False
        client.queued.append(item)
        client.wake.set()
        return True

    async def _sender(self, client: _Client) -> None:
        ws = client.ws
        while not ws.closed:
            await client.wake.wait()
            client.wake.clear()
            try:
                while client.queued:
                    item = client.queued.popleft()
                    if isinstance(item, str):
                        await ws.send_str(item)
                    else:
                        await ws.send_bytes(item)
                values, client.values = client.values, {}
                for message in values.values():
                    await ws.send_bytes(message)  # waits while the socket is full: values keep coalescing
                client.sent += len(values)
                self.pushed += len(values)
            except (ConnectionError, RuntimeError) as exc:
                log.debug("OSCQuery client %d: send failed (%s)", client.ident, exc)
                return

    # ------------------------------------------------------------------ values
    def _value_message(self, path: str, ctx: Any) -> bytes | None:
        found = self.tree.value(path, ctx)
        if found is None:
            return None
        types, value = found
        return encode_message(path, value, types)

    def value_changed(self, *paths: str) -> None:
        """Paths whose value changed (any thread): listeners get the new value within :data:`PUSH_INTERVAL_S`.

        For adapters whose values do not come through the controller (the VRChat bridge's
        ``/avatar/parameters/...``).
        """
        if not self._listeners:
            return
        with self._lock:
            self._dirty.update(p for p in paths if p in self._listeners)
            if self._scheduled or not self._dirty:
                return
            self._scheduled = True
        loop = self._loop
        try:
            if loop is not None:
                loop.call_soon_threadsafe(self._flush_soon)
        except RuntimeError:  # the loop closed while the service stops
            pass

    def _on_knob_event(self, event: KnobEvent) -> None:
        if not self._listeners:
            return  # nobody listens: a knob move costs this test only
        name, c = event.name, event.channel
        prefix = self.handler.prefix
        names = (name, "texture") if name in ("intensity", "balance") else (name,)
        paths = [f"{prefix}/ch/{c + 1}/{n}" for n in names]
        if c == 0:
            paths += [f"{prefix}/{n}" for n in names]
        self.value_changed(*paths)

    def _flush_soon(self) -> None:
        assert self._loop is not None
        self._loop.call_later(PUSH_INTERVAL_S, self._flush)

    def _flush(self) -> None:
        with self._lock:
            dirty, self._dirty = self._dirty, set()
            self._scheduled = False
        self._push(dirty)

    def _push(self, paths: set[str]) -> None:
        ctx = self.tree.context()
        for path in paths:
            listeners = self._listeners.get(path)
            if not listeners:
                continue
            message = self._value_message(path, ctx)
            if message is None:
                continue
            self._last_polled[path] = message
            for client in listeners:
                client.values[path] = message
                client.wake.set()

    async def _poll(self) -> None:
        """Read the listened values every :data:`POLL_S`; push those that changed (values without events)."""
        while True:
            await asyncio.sleep(POLL_S)
            if not self._listeners:
                self._last_polled.clear()
                continue
            ctx = self.tree.context()
            changed = set()
            for path in list(self._listeners):
                message = self._value_message(path, ctx)
                if message is not None and self._last_polled.get(path) != message:
                    changed.add(path)
            if changed:
                self._push(changed)

    async def _refresh(self) -> None:
        """Compare the tree's structure every :data:`REFRESH_S` while WebSocket clients are connected."""
        while True:
            await asyncio.sleep(REFRESH_S)
            if self.clients:
                await self._rebuild()

    async def _rebuild(self) -> None:
        """Rebuild the tree's structure (on a worker thread); tell the clients what changed."""
        self._rebuilt_at = time.monotonic()
        try:
            events = await asyncio.get_running_loop().run_in_executor(None, self.tree.refresh)
        except VibsynthError as exc:
            log.warning("OSCQuery: the tree could not be rebuilt: %s", exc)
            return
        if events:
            self.notify_structure(events)

    def structure_changed(self) -> None:
        """Nodes were added or removed (any thread; e.g. after :meth:`Tree.register`): rebuild and tell the
        clients now instead of within :data:`REFRESH_S`."""
        self.call_in_loop(lambda: asyncio.ensure_future(self._rebuild()))

    def notify_structure(self, events: list[tuple[str, str]]) -> None:
        """Send ``PATH_ADDED`` / ``PATH_REMOVED`` / ``PATH_CHANGED`` to every client (on the loop)."""
        self.structure_events += len(events)
        if len(events) > MAX_QUEUED // 2:  # too many to list: the whole tree changed
            events = [("PATH_CHANGED", "/")]
        for command, path in events:
            if command == "PATH_REMOVED":
                for client in self._listeners.pop(path, set()):
                    client.listens.discard(path)
            text = json.dumps({"COMMAND": command, "DATA": path})
            for client in self.clients:
                self._enqueue(client, text)
