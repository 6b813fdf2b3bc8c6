"""A tap on the control inputs: what the server receives, for monitors and status.

Adapters publish what they receive (an OSC message with its sender, a MIDI message with its
port, knob moves taken by the compiled OSC fast path) and every error they answer. Readers
(``/vibsynth/monitor`` subscribers, ``vibsynth monitor``, the studio's status page) follow the
stream with a cursor.

Cost when nobody listens: one attribute read per message (:attr:`InputTap.active`; the
compiled OSC receive loop reads the one byte of :attr:`InputTap.flag` instead, without the
GIL); the text of an event is only formatted when someone reads. Errors are always kept (the last
:data:`ERRORS_KEPT`), so a status query can show them. Memory is bounded: a ring of
``capacity`` events; a reader that falls behind is told how many it missed.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["InputEvent", "InputTap", "ERRORS_KEPT"]

#: Errors kept for status queries, whoever listens.
ERRORS_KEPT = 16
#: Longest event text kept (a 64 KiB OSC string is shown by its start).
MAX_TEXT = 300


@dataclass(frozen=True)
class InputEvent:
    """One thing the server received (or refused).

    Attributes
    ----------
    seq : int
        Position in the stream (1, 2, ...): a reader's cursor.
    time : float
        Wall-clock time (Unix seconds) of arrival.
    source : str
        ``osc``, ``osc-fast`` (a message the compiled fast path took), ``midi`` or ``error``.
    text : str
        What arrived, as text (at most :data:`MAX_TEXT` characters).
    """

    seq: int
    time: float
    source: str
    text: str


def _clip(text: str) -> str:
    return text if len(text) <= MAX_TEXT else text[: MAX_TEXT - 1] + "…"


class InputTap:
    """Bounded stream of input events with cursors for several readers.

    Parameters
    ----------
    capacity : int
        Events kept for readers; older ones are dropped (a slow reader learns how many).
    clock : callable
        Wall clock (injectable for tests).
    """

    def __init__(self, capacity: int = 2048, *, clock: Callable[[], float] = time.time) -> None:
        self.capacity = int(capacity)
        self.clock = clock
        self._events: deque[InputEvent] = deque(maxlen=self.capacity)
        self._errors: deque[InputEvent] = deque(maxlen=ERRORS_KEPT)
        self._seq = 0
        self._evicted = 0  # seq of the last event pushed out of the ring
        self._readers = 0
        self._lock = threading.Lock()
        #: One byte, 1 while someone reads: a compiled publisher holds this buffer and reads it
        #: without the GIL (see :mod:`vibsynth.control.osc.fast`).
        self.flag = bytearray(1)

    @property
    def active(self) -> bool:
        """True while someone reads the stream (publishers may skip formatting otherwise)."""
        return self._readers > 0

    def attach(self) -> int:
        """Start reading: returns the cursor of the next event."""
        with self._lock:
            self._readers += 1
            self.flag[0] = 1
            return self._seq + 1

    def detach(self) -> None:
        """Stop reading (one :meth:`attach` each)."""
        with self._lock:
            self._readers = max(0, self._readers - 1)
            self.flag[0] = int(self._readers > 0)

    def publish(self, source: str, text: str | Callable[[], str], at: float | None = None) -> None:
        """Add an event when someone reads; ``text`` may be a callable, called only then.

        ``at`` is the wall-clock time of arrival when the publisher learns of it later (now
        otherwise).
        """
        if not self._readers:
            return
        shown = _clip(text() if callable(text) else text)
        with self._lock:
            self._seq += 1
            self._push(InputEvent(self._seq, self.clock() if at is None else at, source, shown))

    def _push(self, event: InputEvent) -> None:
        if len(self._events) == self.capacity:
            self._evicted = self._events[0].seq
        self._events.append(event)

    def error(self, text: str) -> None:
        """Add an error: kept for status queries always, and streamed to readers."""
        with self._lock:
            self._seq += 1
            event = InputEvent(self._seq, self.clock(), "error", _clip(text))
            self._errors.append(event)
            if self._readers:
                self._push(event)

    def read(self, cursor: int, limit: int = 256) -> tuple[list[InputEvent], int, int]:
        """Events from ``cursor`` on.

        Returns
        -------
        events : list of InputEvent
            At most ``limit``, oldest first.
        next_cursor : int
            Cursor to pass next time.
        missed : int
            Events dropped before this reader got them (the ring overflowed).
        """
        with self._lock:
            missed = max(0, self._evicted - cursor + 1)
            events = [e for e in self._events if e.seq >= cursor][:limit]
            next_cursor = events[-1].seq + 1 if events else max(cursor, self._seq + 1)
            return events, next_cursor, missed

    def last_errors(self) -> list[InputEvent]:
        """The last :data:`ERRORS_KEPT` errors, oldest first."""
        with self._lock:
            return list(self._errors)
