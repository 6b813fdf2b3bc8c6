"""``/vibsynth/monitor``: stream what the server receives to subscribed clients (``vibsynth monitor``).

A subscriber gets, every :data:`PUSH_PERIOD_S` at most, one bundle of
``{prefix}/monitor.event d time s source s text`` messages: every OSC message the server
received (with its sender), every knob move the compiled fast path took, every MIDI message
and every error answered (see :mod:`vibsynth.control.tap`). A subscriber that cannot keep up
is told how many events it missed.

Limits: :data:`MAX_SUBSCRIBERS` subscribers; a subscription lasts :data:`LEASE_S` unless
renewed (``vibsynth monitor`` renews it every few seconds), so a client killed without
unsubscribing costs nothing for long; over UDP only clients on this machine may subscribe
(a spoofed subscription could otherwise point the stream at a victim); other hosts use TCP.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from vibsynth.control.osc.codec import IMMEDIATE, Message, encode_bundle, encode_message
from vibsynth.control.osc.workers import PeerLike
from vibsynth.control.tap import InputTap
from vibsynth.errors import VibsynthError

__all__ = ["MonitorWorker", "MAX_SUBSCRIBERS", "LEASE_S", "PUSH_PERIOD_S", "describe_message", "describe_sender"]

MAX_SUBSCRIBERS = 8
LEASE_S = 30.0
PUSH_PERIOD_S = 0.05
#: Events per pushed bundle (each at most ~350 bytes: a bundle stays far below a datagram's 64 KiB).
EVENTS_PER_PUSH = 64
#: Arguments shown of one message (the rest is ``…``).
ARGS_SHOWN = 16


def describe_sender(address: tuple[str, int] | None, datagram: bool = True) -> str:
    """``udp 127.0.0.1:5000`` (``tcp ...`` for a stream peer; ``?`` when unknown)."""
    if not address:
        return "?"
    return f"{'udp' if datagram else 'tcp'} {address[0]}:{address[1]}"


def _show_arg(value: object) -> str:
    if isinstance(value, str):
        return '"' + (value if len(value) <= 64 else value[:63] + "…") + '"'
    if isinstance(value, (bytes, bytearray)):
        return f"<blob {len(value)} bytes>"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def describe_message(msg: Message, sender: str, at_frame: int | None = None) -> str:
    """One monitor line, as received (like oscdump): ``/vibsynth/intensity f 0.5  (udp 127.0.0.1:5000)``.

    The address and type tags are the sender's, untouched (a global address is not expanded
    into the channels it reaches); ``sender`` comes from :func:`describe_sender`.
    """
    args = " ".join(_show_arg(a) for a in msg.args[:ARGS_SHOWN]) + (" …" if len(msg.args) > ARGS_SHOWN else "")
    when = f" at frame {at_frame}" if at_frame is not None else ""
    return f"{msg.address} {msg.types} {args}".rstrip() + f"  ({sender}{when})"


@dataclass
class _Subscriber:
    peer: PeerLike
    cursor: int
    expires: float


class MonitorWorker:
    """Pushes the input tap's events to subscribed peers from its own thread.

    Parameters
    ----------
    tap : InputTap
    prefix : str
        Address prefix of the pushed ``monitor.event`` messages.
    clock : callable
        Monotonic clock (injectable for tests).
    """

    def __init__(self, tap: InputTap, prefix: str, *, clock: Callable[[], float] = time.monotonic) -> None:
        self.tap = tap
        self.address = f"{prefix}/monitor.event"
        self.clock = clock
        self.pushes = 0
        self._subs: dict[tuple, _Subscriber] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __len__(self) -> int:
        return len(self._subs)

    def subscribe(self, peer: PeerLike) -> None:
        """Add or renew a subscription (for :data:`LEASE_S`).

        The caller refuses UDP peers on other hosts (see the module docstring).

        Raises
        ------
        VibsynthError
            Too many subscribers.
        """
        with self._lock:
            sub = self._subs.get(peer.key)
            if sub is None:
                if len(self._subs) >= MAX_SUBSCRIBERS:
                    raise VibsynthError(f"too many monitor subscribers (max {MAX_SUBSCRIBERS})")
                sub = self._subs[peer.key] = _Subscriber(peer, self.tap.attach(), 0.0)
            sub.peer = peer
            sub.expires = self.clock() + LEASE_S

    def unsubscribe(self, peer: PeerLike) -> bool:
        """Remove a subscription; True if there was one."""
        with self._lock:
            sub = self._subs.pop(peer.key, None)
        if sub is not None:
            self.tap.detach()
        return sub is not None

    def pump(self) -> None:
        """Send each subscriber what arrived since its last push; drop expired subscriptions."""
        now = self.clock()
        with self._lock:
            expired = [key for key, sub in self._subs.items() if sub.expires <= now]
            for key in expired:
                del self._subs[key]
                self.tap.detach()
            subs = list(self._subs.values())
        for sub in subs:
            events, sub.cursor, missed = self.tap.read(sub.cursor, EVENTS_PER_PUSH)
            messages = []
            if missed:
                messages.append(
                    encode_message(self.address, (time.time(), "error", f"{missed} events missed (too slow)"), "dss")
                )
            messages += [encode_message(self.address, (e.time, e.source, e.text), "dss") for e in events]
            if not messages:
                continue
            sub.peer.send(messages[0] if len(messages) == 1 else encode_bundle(IMMEDIATE, messages))
            self.pushes += 1

    def start(self) -> None:
        """Start the push thread."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-osc-monitor", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the push thread and drop every subscription."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        with self._lock:
            for _ in self._subs:
                self.tap.detach()
            self._subs.clear()

    def _run(self) -> None:
        while not self._stop.wait(PUSH_PERIOD_S):
            if self._subs:
                self.pump()
