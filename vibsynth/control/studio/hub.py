"""Pushes to the open pages: every change is posted under a key, only the latest per key is sent.

Changes come from any thread (the OSC receive loop, MIDI, the preset watcher, the spectrum
worker) through :meth:`Hub.post`, which only stores the message under its key and, once per
burst, wakes the event loop (``call_soon_threadsafe``). The loop hands the batch to every
page; each page has its own sender task that sends what is pending in one WebSocket frame
and waits for the socket to drain before the next. So a 10,000 messages/s OSC flood costs a
dictionary assignment per message, and whatever the rate or a page's speed, memory is
bounded by the number of keys (channels x knobs, plus a bounded number of others), and a
page sees the newest value of everything within one loop turn plus one send.
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from collections.abc import Hashable
from dataclasses import dataclass, field
from typing import Any

from aiohttp import web

__all__ = ["Hub", "Page", "MAX_KEYS"]

log = logging.getLogger(__name__)

#: Most distinct keys waiting at once (per page and in the incoming batch); more are dropped and counted.
MAX_KEYS = 4096


@dataclass(eq=False)
class Page:
    """One open page (a WebSocket), its pending pushes and its state."""

    ws: web.WebSocketResponse
    ident: int
    pending: dict[Hashable, dict[str, Any]] = field(default_factory=dict)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    channel: int = 0  # 0-based channel whose spectrum the page shows
    sender: asyncio.Task[None] | None = None


class Hub:
    """The set of open pages and the coalescing push path.

    Parameters
    ----------
    loop : asyncio.AbstractEventLoop
        The studio's event loop (pages are only touched on it).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.pages: set[Page] = set()
        self._lock = threading.Lock()
        self._incoming: dict[Hashable, dict[str, Any]] = {}
        self._scheduled = False
        self._next_id = 0
        self.posted = 0
        self.sent = 0
        self.dropped = 0
        self.closed = False

    # ------------------------------------------------------------------ any thread
    def post(self, key: Hashable, message: dict[str, Any]) -> None:
        """Queue ``message`` for every page; a later message under the same key replaces it."""
        with self._lock:
            self.posted += 1
            if key not in self._incoming and len(self._incoming) >= MAX_KEYS:
                self.dropped += 1
                return
            self._incoming[key] = message
            if self._scheduled or self.closed:
                return
            self._scheduled = True
        try:
            self.loop.call_soon_threadsafe(self._dispatch)
        except RuntimeError:  # the loop closed while the service stops
            pass

    @property
    def page_count(self) -> int:
        return len(self.pages)

    # ------------------------------------------------------------------ the loop
    def _dispatch(self) -> None:
        with self._lock:
            batch, self._incoming = self._incoming, {}
            self._scheduled = False
        for page in self.pages:
            self._queue(page, batch)

    def _queue(self, page: Page, batch: dict[Hashable, dict[str, Any]]) -> None:
        pending = page.pending
        for key, message in batch.items():
            if key not in pending and len(pending) >= MAX_KEYS:
                self.dropped += 1
                continue
            pending[key] = message
        if pending:
            page.wake.set()

    def send_to(self, page: Page, key: Hashable, message: dict[str, Any]) -> None:
        """Queue a message for one page only (on the loop)."""
        self._queue(page, {key: message})

    def attach(self, ws: web.WebSocketResponse) -> Page:
        """Register an open WebSocket and start its sender (on the loop)."""
        self._next_id += 1
        page = Page(ws=ws, ident=self._next_id)
        self.pages.add(page)
        page.sender = asyncio.ensure_future(self._sender(page))
        return page

    async def detach(self, page: Page) -> None:
        """Forget a page and stop its sender."""
        self.pages.discard(page)
        if page.sender is not None:
            page.sender.cancel()
            try:
                await page.sender
            except (asyncio.CancelledError, Exception):  # noqa: BLE001 - it is going away either way
                pass

    async def _sender(self, page: Page) -> None:
        ws = page.ws
        while not ws.closed:
            await page.wake.wait()
            page.wake.clear()
            if not page.pending:
                continue
            messages = list(page.pending.values())
            page.pending = {}
            text = json.dumps(messages[0] if len(messages) == 1 else {"type": "batch", "messages": messages})
            try:
                await ws.send_str(text)  # waits while the socket's buffer is full: pending keeps coalescing
            except (ConnectionError, RuntimeError) as exc:
                log.debug("studio page %d: send failed (%s)", page.ident, exc)
                return
            self.sent += len(messages)

    async def close(self) -> None:
        """Close every page's socket (going away) and stop the senders."""
        with self._lock:
            self.closed = True
        for page in list(self.pages):
            await page.ws.close(code=1001, message=b"vibsynth is stopping")
            await self.detach(page)
