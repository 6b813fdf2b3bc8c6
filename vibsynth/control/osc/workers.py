"""Background helpers of the OSC server: pushed knob changes (/notify) and deferred /sync replies.

Neither runs on the receive thread, so a slow subscriber or an engine that has not
caught up never delays incoming messages.

* :class:`Notifier` keeps, per subscriber, the latest value of every changed knob
  (coalescing: 100 changes of one knob between two pushes become one value) and
  pushes them at most ``rate_hz`` times per second, as one datagram (a bundle when
  several values changed).
* :class:`SyncWorker` answers ``/sync id`` with ``/synced id`` once the engine has
  applied every command submitted before it, in the order the requests arrived.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from vibsynth.control.controller import Controller, KnobEvent
from vibsynth.control.osc.codec import IMMEDIATE, encode_bundle, encode_message

__all__ = ["PeerLike", "Notifier", "SyncWorker", "setter_message"]

log = logging.getLogger(__name__)


class PeerLike(Protocol):
    """A reply destination (see :mod:`vibsynth.control.osc.transport`)."""

    @property
    def key(self) -> tuple: ...

    def send(self, data: bytes) -> bool: ...


def setter_message(prefix: str, channel: int | None, name: str, value: object) -> bytes:
    """Encode a knob value in the form that would set it, e.g. ``/vibsynth/ch/2/intensity f``.

    ``glide`` is in ms, ``mute`` an int 0/1, ``preset`` a string (``""`` = none); ``driver``
    (the layer driving the channel's knobs: knobs, sources or clip) is reported as a string,
    though no client sets it.
    """
    base = prefix if channel is None else f"{prefix}/ch/{channel + 1}"
    if name == "glide":
        return encode_message(f"{base}/glide", (float(value) * 1000.0,), "f")  # type: ignore[arg-type]
    if name == "mute":
        return encode_message(f"{base}/mute", (int(bool(value)),), "i")
    if name in ("preset", "driver"):
        return encode_message(f"{base}/{name}", ("" if value is None else str(value),), "s")
    return encode_message(f"{base}/{name}", (float(value),), "f")  # type: ignore[arg-type]


@dataclass
class _Subscriber:
    peer: PeerLike
    pending: dict[tuple[int, str], object] = field(default_factory=dict)
    next_due: float = 0.0


class Notifier:
    """Rate-limited, coalescing pushes of knob changes to subscribed peers.

    Parameters
    ----------
    controller : Controller
        Source of changes (any source: OSC, MIDI, presets).
    prefix : str
        Address prefix of the pushed setter-form messages.
    rate_hz : float
        Maximum pushes per second per subscriber.
    max_subscribers : int
        Further subscriptions are refused.
    clock : callable
        Monotonic clock (injectable for tests).
    """

    def __init__(
        self,
        controller: Controller,
        prefix: str,
        *,
        rate_hz: float = 30.0,
        max_subscribers: int = 32,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.controller = controller
        self.prefix = prefix
        self.period = 1.0 / rate_hz if rate_hz > 0 else 0.0
        self.max_subscribers = max_subscribers
        self.clock = clock
        self.pushes = 0
        self._subs: dict[tuple, _Subscriber] = {}
        self._cond = threading.Condition()
        self._stop = False
        self._thread: threading.Thread | None = None
        self._unsubscribe: Callable[[], None] | None = None

    # -------------------------------------------------------------- subscriptions
    def __len__(self) -> int:
        return len(self._subs)

    def subscribe(self, peer: PeerLike) -> bool:
        """Add a peer (idempotent) and queue the full current state for it; False if full."""
        snapshot: dict[tuple[int, str], object] = {}
        for ch, state in enumerate(self.controller.state()):
            snapshot.update(
                {
                    (ch, "intensity"): state.intensity,
                    (ch, "balance"): state.balance,
                    (ch, "glide"): state.glide_s,
                    (ch, "mute"): state.muted,
                }
            )
            if state.preset is not None:
                snapshot[(ch, "preset")] = state.preset
        with self._cond:
            sub = self._subs.get(peer.key)
            if sub is None:
                if len(self._subs) >= self.max_subscribers:
                    return False
                sub = self._subs[peer.key] = _Subscriber(peer)
            sub.pending.update(snapshot)
            self._cond.notify()
        return True

    def unsubscribe(self, peer: PeerLike) -> bool:
        """Remove a peer; True if it was subscribed."""
        with self._cond:
            return self._subs.pop(peer.key, None) is not None

    def on_event(self, event: KnobEvent) -> None:
        """Controller listener: remember the latest value (cheap; called on the changing thread)."""
        if not self._subs:
            return
        with self._cond:
            for sub in self._subs.values():
                sub.pending[(event.channel, event.name)] = event.value
            self._cond.notify()

    # -------------------------------------------------------------- pushing
    def pump(self, now: float | None = None) -> float | None:
        """Send what is due; return the time of the next due push (None: nothing pending)."""
        now = self.clock() if now is None else now
        sends = []
        next_due = None
        with self._cond:
            for sub in self._subs.values():
                if not sub.pending:
                    continue
                if now < sub.next_due:
                    next_due = sub.next_due if next_due is None else min(next_due, sub.next_due)
                    continue
                messages = [setter_message(self.prefix, ch, name, value) for (ch, name), value in sub.pending.items()]
                sub.pending.clear()
                sub.next_due = now + self.period
                sends.append((sub.peer, messages[0] if len(messages) == 1 else encode_bundle(IMMEDIATE, messages)))
        for peer, data in sends:
            peer.send(data)
            self.pushes += 1
        return next_due

    def start(self) -> None:
        """Attach to the controller and start the push thread."""
        self._unsubscribe = self.controller.subscribe(self.on_event)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-notify", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Detach and stop."""
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None
        with self._cond:
            self._stop = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _run(self) -> None:
        while True:
            next_due = self.pump()
            with self._cond:
                if self._stop:
                    return
                if next_due is None:
                    if not any(s.pending for s in self._subs.values()):
                        self._cond.wait(timeout=1.0)
                else:
                    self._cond.wait(timeout=max(0.0, next_due - self.clock()))


class SyncWorker:
    """Answers deferred ``/sync`` requests in arrival order.

    Parameters
    ----------
    controller : Controller
    reply : callable
        ``reply(peer, sync_id, ok)`` sends ``/synced`` (ok) or an error (timed out).
    timeout_s : float
        Give up (error reply) when the engine has not caught up after this long.
    """

    def __init__(
        self, controller: Controller, reply: Callable[[PeerLike, int, bool], None], *, timeout_s: float = 12.0
    ) -> None:
        self.controller = controller
        self.reply = reply
        self.timeout_s = timeout_s
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._submitted = 0  # written by the receive thread only
        self._done = 0  # written by the worker only

    @property
    def idle(self) -> bool:
        """True when no request is waiting (a new one may then be answered at once)."""
        return self._submitted == self._done

    def submit(self, peer: PeerLike, sync_id: int) -> None:
        """Queue a request (called on the receive thread; never blocks)."""
        self._submitted += 1
        self._queue.put((peer, sync_id, time.monotonic() + self.timeout_s))

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-sync", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join(timeout=2.0)
            self._thread = None

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            peer, sync_id, deadline = item
            ok = False
            while True:
                if self.controller.sync(timeout_s=0.05):
                    ok = True
                    break
                if time.monotonic() >= deadline:
                    break
            try:
                self.reply(peer, sync_id, ok)
            finally:
                self._done += 1
