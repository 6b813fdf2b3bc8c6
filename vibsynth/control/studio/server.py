"""The studio's HTTP + WebSocket server: an aiohttp application on its own event loop, in a daemon thread.

Nothing here runs on the audio thread or takes a lock the audio callback needs: knob moves
go through the :class:`~vibsynth.control.controller.Controller` (a short lock and a
lock-free hand-off to the engine) exactly as OSC's do. Slow work (preset files, analysing
an uploaded recording, the measured spectrum) runs on worker threads, never on the loop.

Routes (all behind :class:`~vibsynth.control.studio.security.Gate`):

``GET /``                   the page (``?token=`` sets the cookie and redirects here)
``GET /static/<file>``      its CSS and ES modules (package data, a fixed list)
``GET /ws``                 the live WebSocket (:mod:`~vibsynth.control.studio.commands`, pushes)
``GET /api/state``          channels, limits, knobs, driving layer, extensions
``GET /api/status``         :mod:`~vibsynth.control.studio.status`
``/api/presets...``         :mod:`~vibsynth.control.studio.presets`
``/api/recording...``       :mod:`~vibsynth.control.studio.recording`
``GET /api/spectrum``       :mod:`~vibsynth.control.studio.spectrum`
``/ext/<name>/...``         extensions (:class:`~vibsynth.control.studio.extension.StudioExtension`)
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSCloseCode, WSMsgType, web

from vibsynth._version import __version__
from vibsynth.control.controller import Controller, KnobEvent
from vibsynth.control.loop_server import LoopServer
from vibsynth.control.studio.commands import (
    ALWAYS,
    COALESCED,
    MAX_MESSAGE_BYTES,
    Command,
    MessageError,
    Throttle,
    apply_command,
    parse_message,
)
from vibsynth.control.studio.extension import StudioExtension
from vibsynth.control.studio.hub import Hub, Page
from vibsynth.control.studio.security import BODY_CAP, Gate, new_token
from vibsynth.control.websocket import StrictWebSocketResponse, UnmaskedFrame, accept
from vibsynth.errors import ConfigError, VibsynthError

__all__ = ["StudioServer", "MAX_PAGES", "UPLOAD_PATHS"]

log = logging.getLogger(__name__)

#: Most pages open at once (each costs a socket and a sender task).
MAX_PAGES = 32
#: Routes whose body may be as large as an upload (they stream it and stop at the cap).
UPLOAD_PATHS = frozenset({"/api/recording"})
#: Error answers per second to one page (more are counted, not sent).
ERROR_REPLY_RATE = 20.0

_CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}


def static_dir() -> Path:
    """The page's files (package data ``vibsynth/control/studio/static``)."""
    return Path(str(resources.files("vibsynth.control.studio").joinpath("static")))


def _static_files(folder: Path) -> dict[str, Path]:
    """Relative path -> file, for every servable file (the only paths ``/static/`` answers)."""
    return {
        p.relative_to(folder).as_posix(): p
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.suffix in _CONTENT_TYPES and not p.name.startswith(".")
    }


class StudioServer(LoopServer):
    """The studio (the adapter's ControlServer: ``start``, ``stop``, ``describe``).

    Parameters
    ----------
    controller : Controller
    host, port : str, int
        Where to listen (port 0 = any free port).
    token : str, optional
        Default: a fresh random token.
    library : PresetLibrary, optional
        The service's preset library (None: the presets panel says there is none).
    extensions : sequence of StudioExtension
    port_fallback : bool
        When the port is taken, listen on a free one (with a warning) instead of failing.
    status_sources : sequence of callables
        Each returns ``(key, value)`` pairs for the status panel (the OSC server's
        ``/status`` content, MIDI counters); see :mod:`~vibsynth.control.studio.status`.
    learn : callable, optional
        ``learn(knob) -> bool``: arm MIDI learn (False: no MIDI input running).
    """

    name = "studio"
    title = "studio"
    bind_hint = "(set studio.port or --studio-port, or --no-studio)"

    def __init__(
        self,
        controller: Controller,
        *,
        host: str = "127.0.0.1",
        port: int = 9571,
        token: str | None = None,
        library: Any = None,
        extensions: Sequence[StudioExtension] = (),
        port_fallback: bool = False,
        status_sources: Sequence[Callable[[], list[tuple[str, object]]]] = (),
        learn: Callable[[str], bool] | None = None,
    ) -> None:
        super().__init__(host, port, port_fallback=port_fallback)
        self.controller = controller
        self.token = token or new_token()
        self.library = library
        self.extensions = tuple(extensions)
        names = [e.name for e in self.extensions]
        for ext in self.extensions:
            ext.check()
        if len(set(names)) != len(names):
            raise ConfigError(f"studio extensions with the same name: {', '.join(sorted(names))}")
        self.status_sources = tuple(status_sources)
        self.learn = learn
        self.gate: Gate | None = None
        self.hub: Hub | None = None
        self.workers = ThreadPoolExecutor(max_workers=2, thread_name_prefix="vibsynth-studio-work")
        self._unsubscribe: Callable[[], None] | None = None
        self._static = _static_files(static_dir())
        self._on_pages_changed: list[Callable[[int], None]] = []
        self.plugins: list[Any] = []  # panels with start/stop (spectrum worker, preset watcher hook)

    # ------------------------------------------------------------------ life cycle
    @property
    def url(self) -> str:
        """The address to open, with the token (a wildcard bind is shown as 127.0.0.1)."""
        host = "127.0.0.1" if self.host in ("0.0.0.0", "", "::") else self.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/?token={self.token}"

    def describe(self) -> str:
        """One line for the start-up banner (the URL with the token is printed on its own line)."""
        text = f"studio on http://{self.host}:{self.port}/"
        if self.port != self.requested_port and self.requested_port != 0:
            text += f" (port {self.requested_port} was in use)"
        if self.gate is not None and not self.gate.loopback:
            text += ", reachable from the network (token required)"
        return text

    def start(self) -> None:
        """Bind and start the event loop thread.

        Raises
        ------
        ConfigError
            The address cannot be bound (port in use without fallback, unknown host...).
        """
        self.start_loop("vibsynth-studio")
        for plugin in self.plugins:
            plugin.start()
        self._unsubscribe = self.controller.subscribe(self._on_knob_event)
        log.info("%s", self.describe())

    def stop(self) -> None:
        """Close the pages, stop the loop and the workers (idempotent)."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        for plugin in self.plugins:
            plugin.stop()
        self.stop_loop()
        self.workers.shutdown(wait=False, cancel_futures=True)

    async def _make_app(self) -> web.Application:
        self.hub = Hub(asyncio.get_running_loop())
        return self.make_app()

    async def _bound(self) -> None:
        assert self.gate is not None
        self.gate.port = self.port
        self.gate.cookie = f"vibsynth_studio_{self.port}"

    async def _closing(self) -> None:
        if self.hub is not None:
            await self.hub.close()

    # ------------------------------------------------------------------ the application
    def make_app(self) -> web.Application:
        """The aiohttp application: middlewares, the studio's routes, then the extensions'."""
        self.gate = Gate(self.token, port=self.requested_port, bind_host=self.host, upload_paths=UPLOAD_PATHS)
        app = web.Application(middlewares=[self.gate.middleware, _unexpected], client_max_size=BODY_CAP)
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{path:.+}", self._static_file)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/api/state", self._state)
        for ext in self.extensions:
            app.router.add_get(f"{ext.prefix}tab.js", self._extension_script(ext))
        for panel in self.panels():
            panel.add_routes(app)
        for ext in self.extensions:
            before = {r.resource.canonical for r in app.router.routes() if r.resource is not None}
            if ext.add_routes is not None:
                ext.add_routes(app, self)
            added = {r.resource.canonical for r in app.router.routes() if r.resource is not None} - before
            outside = sorted(path for path in added if not path.startswith(ext.prefix))
            if outside:
                raise ConfigError(
                    f"studio extension {ext.name!r} added routes outside {ext.prefix}: {', '.join(outside)}"
                )
        return app

    def panels(self) -> list[Any]:
        """The panels with routes of their own (presets, recording, status, spectrum)."""
        return [p for p in self.plugins if hasattr(p, "add_routes")]

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(self._static["index.html"], headers={"Content-Type": "text/html; charset=utf-8"})

    async def _static_file(self, request: web.Request) -> web.StreamResponse:
        path = self._static.get(request.match_info["path"])
        if path is None:
            raise web.HTTPNotFound(text="no such file\n")
        return web.FileResponse(path, headers={"Content-Type": f"{_CONTENT_TYPES[path.suffix]}; charset=utf-8"})

    def _extension_script(self, ext: StudioExtension) -> Callable[[web.Request], Any]:
        async def script(request: web.Request) -> web.StreamResponse:
            return web.FileResponse(ext.script, headers={"Content-Type": "text/javascript; charset=utf-8"})

        return script

    # ------------------------------------------------------------------ state
    def channel_state(self) -> list[dict[str, Any]]:
        """Each channel's knobs as the page shows them (1-based channel, glide in ms)."""
        driver = getattr(self.controller, "driver", None)
        out = []
        for c, s in enumerate(self.controller.state()):
            out.append(
                {
                    "channel": c + 1,
                    "intensity": s.intensity,
                    "balance": s.balance,
                    "glide_ms": s.glide_s * 1000.0,
                    "mute": s.muted,
                    "preset": s.preset,
                    "driver": driver(c) if callable(driver) else "knobs",
                }
            )
        return out

    def hello(self) -> dict[str, Any]:
        """Everything a page needs to draw itself (the first WebSocket message, and ``/api/state``)."""
        limits = self.controller.limits
        return {
            "type": "hello",
            "version": __version__,
            "channels": self.controller.channels,
            "limits": {
                "intensity_min": 0.0,
                "intensity_max": 1.0,
                "balance_min": limits.balance_min,
                "balance_max": limits.balance_max,
                "glide_max_ms": limits.glide_max_s * 1000.0,
            },
            "state": self.channel_state(),
            "extensions": [{"name": e.name, "title": e.title, "script": f"{e.prefix}tab.js"} for e in self.extensions],
            "presets": self.library is not None,
        }

    async def _state(self, request: web.Request) -> web.StreamResponse:
        return web.json_response(self.hello())

    # ------------------------------------------------------------------ pushes (any thread)
    def _on_knob_event(self, event: KnobEvent) -> None:
        hub = self.hub
        if hub is None or not hub.pages:
            return
        value: Any = event.value
        name = event.name
        if name == "glide" and isinstance(value, (int, float)):
            name, value = "glide_ms", float(value) * 1000.0
        hub.post(
            ("knob", event.channel, name),
            {"type": "knob", "channel": event.channel + 1, "name": name, "value": value, "source": event.source},
        )

    def publish(self, extension: str, key: str, data: Any) -> None:
        """Push extension data to every page (any thread; the newest per (extension, key) is sent)."""
        if self.hub is not None:
            self.hub.post(("ext", extension, key), {"type": "ext", "extension": extension, "key": key, "data": data})

    def post(self, key: Any, message: dict[str, Any]) -> None:
        """Push a message of the studio's own panels to every page (any thread, coalesced per key)."""
        if self.hub is not None:
            self.hub.post(key, message)

    def on_pages_changed(self, callback: Callable[[int], None]) -> None:
        """``callback(pages)`` whenever a page connects, leaves or changes the channel it watches (on the loop)."""
        self._on_pages_changed.append(callback)

    # ------------------------------------------------------------------ the WebSocket
    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        assert self.hub is not None and self.gate is not None
        if len(self.hub.pages) >= MAX_PAGES:
            return self.gate.refuse("pages", 503, f"too many studio pages open (max {MAX_PAGES}); close one")
        ws = StrictWebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, heartbeat=20.0, compress=False)
        if not await accept(ws, request):  # the client reset during the handshake: nobody to answer
            return web.Response(status=400)
        page = self.hub.attach(ws)
        self.hub.send_to(page, ("hello",), self.hello())
        self._pages_changed()
        session = _Session(self, page)
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    try:
                        session.receive(msg.data)
                    except Exception as exc:  # noqa: BLE001 - a bug answers this message, never drops the page
                        log.exception("studio: handling a page's message failed")
                        session.refuse(exc, None, count=False)
                elif msg.type == WSMsgType.BINARY:
                    session.refuse(MessageError("binary messages are not understood; send JSON text"), None)
                elif msg.type == WSMsgType.ERROR:  # aiohttp has closed it: 1009 too large, 1002 protocol error
                    code = getattr(msg.data, "code", None) or ws.close_code
                    if isinstance(msg.data, UnmaskedFrame):
                        self.gate.count("unmasked")
                    else:
                        self.gate.count("too_large" if code == WSCloseCode.MESSAGE_TOO_BIG else "malformed")
                    break
        finally:
            session.close()
            await self.hub.detach(page)
            self._pages_changed()
        return ws

    def _pages_changed(self) -> None:
        count = self.hub.page_count if self.hub is not None else 0
        for callback in self._on_pages_changed:
            try:
                callback(count)
            except Exception:  # noqa: BLE001 - a panel's bug must not break the socket
                log.exception("studio: page count callback failed")


@web.middleware
async def _unexpected(request: web.Request, handler: Callable[[web.Request], Any]) -> web.StreamResponse:
    """A bug in a handler answers one line (500) and is logged with its traceback, never an HTML page."""
    try:
        response: web.StreamResponse = await handler(request)
        return response
    except web.HTTPException:
        raise
    except Exception as exc:  # noqa: BLE001 - the last line of defence of every route
        log.exception("studio: %s %s failed", request.method, request.path)
        message = f"unexpected {type(exc).__name__}: {exc} (a bug: please report it; the log has the details)"
        return web.json_response({"message": message}, status=500)


class _Session:
    """One page's message handling: validation, budget, deferred knob moves, answers."""

    def __init__(self, server: StudioServer, page: Page) -> None:
        self.server = server
        self.page = page
        self.throttle = Throttle()
        self.errors = Throttle(rate=ERROR_REPLY_RATE, burst=ERROR_REPLY_RATE)
        self.flush_handle: asyncio.TimerHandle | None = None

    def receive(self, text: str) -> None:
        server = self.server
        try:
            command = parse_message(text, server.controller.channels)
        except MessageError as exc:
            self.refuse(exc, None)
            return
        if command.type == "watch":
            assert command.channels is not None
            self.page.channel = command.channels[0]
            self.ack(command)
            server._pages_changed()  # a panel may push what the page now watches
            return
        deferred = self.throttle.deferred
        if command.type in COALESCED and (deferred or not self.throttle.take()):
            # Behind moves already waiting (or over budget): wait too, so nothing older lands after it.
            # Re-inserted at the end: the waiting moves keep the order of their newest arrival.
            deferred.pop(command.key, None)
            deferred[command.key] = command
            if self.flush_handle is None:
                loop = asyncio.get_running_loop()
                self.flush_handle = loop.call_later(self.throttle.wait_s(), self.flush)
            return
        if command.type not in COALESCED and not self.throttle.take() and command.type not in ALWAYS:
            assert server.gate is not None
            server.gate.count("flood")
            self.refuse(MessageError("too many messages: slow down"), command.id, count=False)
            return
        self.drain()  # a mute, preset or panic comes after every move sent before it
        self.apply(command)

    def flush(self) -> None:
        """Apply the deferred knob moves the budget allows (the newest per channel and knob, in order)."""
        self.flush_handle = None
        deferred = self.throttle.deferred
        while deferred and self.throttle.take():
            key = next(iter(deferred))
            self.apply(deferred.pop(key))
        if deferred:
            self.flush_handle = asyncio.get_running_loop().call_later(self.throttle.wait_s(), self.flush)

    def drain(self) -> None:
        """Apply every deferred move now (at most one per key: bounded), before a command that must follow them."""
        deferred = self.throttle.deferred
        while deferred:
            self.apply(deferred.pop(next(iter(deferred))))

    def apply(self, command: Command) -> None:
        try:
            apply_command(self.server.controller, command, learn=self.server.learn)
        except VibsynthError as exc:
            self.refuse(exc, command.id, count=False)
            return
        self.ack(command)

    def ack(self, command: Command) -> None:
        if command.id is not None and self.server.hub is not None:
            self.server.hub.send_to(self.page, ("ack",), {"type": "ack", "id": command.id})

    def refuse(self, exc: Exception, ident: str | int | None, *, count: bool = True) -> None:
        server = self.server
        if count and server.gate is not None:
            server.gate.count("malformed")
        server.controller.count_error("studio")
        if self.errors.take() and server.hub is not None:
            server.hub.send_to(self.page, ("error",), {"type": "error", "id": ident, "message": str(exc)})

    def close(self) -> None:
        if self.flush_handle is not None:
            self.flush_handle.cancel()
            self.flush_handle = None
