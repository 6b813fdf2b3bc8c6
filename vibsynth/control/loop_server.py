"""An aiohttp application on its own event loop in a daemon thread: the studio's and OSCQuery's servers.

:class:`LoopServer` binds (falling back to a free port when asked and the port is taken),
reports a bind failure in the caller's thread as one :class:`~vibsynth.errors.ConfigError`
line, and stops the loop. A subclass builds its application in :meth:`LoopServer._make_app`
and may hook :meth:`LoopServer._bound` (the port is known) and :meth:`LoopServer._closing`
(before the runner is cleaned up: close the sockets).
"""

from __future__ import annotations

import asyncio
import errno
import logging
import os
import threading

from aiohttp import web

from vibsynth.errors import ConfigError, VibsynthError

__all__ = ["LoopServer"]

log = logging.getLogger(__name__)


class LoopServer:
    """The loop thread and the listening site of an aiohttp application.

    Parameters
    ----------
    host, port : str, int
        Where to listen (port 0 = any free port).
    port_fallback : bool
        When the port is taken, listen on a free one (with a warning) instead of failing.
    """

    #: Shown in logs and errors ("studio", "OSCQuery").
    title = "server"
    #: What to do about a port that cannot be bound (the end of the error line).
    bind_hint = ""

    def __init__(self, host: str, port: int, *, port_fallback: bool = False) -> None:
        self.host = host
        self.requested_port = int(port)
        self.port = int(port)
        self.port_fallback = port_fallback
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._runner: web.AppRunner | None = None

    # ------------------------------------------------------------------ hooks
    async def _make_app(self) -> web.Application:
        """The application to serve (on the loop)."""
        raise NotImplementedError

    async def _bound(self) -> None:
        """Called on the loop once :attr:`port` is the bound port."""

    async def _closing(self) -> None:
        """Called on the loop before the runner is cleaned up."""

    # ------------------------------------------------------------------ life cycle
    def start_loop(self, thread_name: str) -> None:
        """Start the loop thread, bind, and return once serving.

        Raises
        ------
        ConfigError
            The address cannot be bound (port in use without fallback, unknown host...).
        """
        self._ready.clear()
        self._start_error = None
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._start_error is None:
            return
        self._thread.join(5.0)
        self._thread = None
        exc = self._start_error
        if isinstance(exc, VibsynthError):
            raise exc
        reason = os.strerror(exc.errno) if isinstance(exc, OSError) and exc.errno else str(exc)
        raise ConfigError(
            f"{self.title}: cannot listen on {self.host}:{self.requested_port}: {reason} {self.bind_hint}".rstrip()
        ) from None

    def stop_loop(self) -> None:
        """Stop the loop (the hooks close what is open) and wait for the thread (idempotent)."""
        loop, thread = self._loop, self._thread
        if loop is not None and thread is not None and thread.is_alive():
            loop.call_soon_threadsafe(loop.stop)
            thread.join(5.0)
        self._thread = None

    def call_in_loop(self, callback: object) -> None:
        """Run ``callback()`` on the loop (from any thread)."""
        if self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(callback)  # type: ignore[arg-type]

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        self._loop = loop
        try:
            loop.run_until_complete(self._startup())
        except Exception as exc:  # noqa: BLE001 - reported by start_loop() in the caller's thread
            self._start_error = exc
            self._ready.set()
            loop.run_until_complete(self._cleanup())
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._cleanup())
            loop.close()

    async def _startup(self) -> None:
        app = await self._make_app()
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await self._runner.setup()
        try:
            site = web.TCPSite(self._runner, self.host, self.requested_port)
            await site.start()
        except OSError as exc:
            if not (self.port_fallback and exc.errno == errno.EADDRINUSE):
                raise
            log.warning("%s: port %d is in use; listening on a free port instead", self.title, self.requested_port)
            site = web.TCPSite(self._runner, self.host, 0)
            await site.start()
        server = site._server  # noqa: SLF001 - aiohttp exposes the bound port only here
        sockets = getattr(server, "sockets", None) or []
        self.port = int(sockets[0].getsockname()[1]) if sockets else self.requested_port
        await self._bound()

    async def _cleanup(self) -> None:
        await self._closing()
        if self._runner is not None:
            await self._runner.cleanup()
