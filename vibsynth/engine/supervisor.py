"""Supervision of a real-time output stream: loss detection, retry with back-off, bounded calls.

Works whatever renders the audio (a Python or a compiled callback): it watches

* a **heartbeat** counter that the audio callback advances (``engine.stats.blocks``),
* the stream's own health (``host.stream_fault()``: PortAudio's ``active`` flag, the
  finished callback, errors),

and drives a small state machine::

    starting --first heartbeat--> streaming --fault / no heartbeat--> device lost
    device lost --retry (back-off 0.25 s doubling to 2 s)--> recovering --heartbeat--> streaming

Every call that may block inside a driver goes through :func:`call_with_timeout`: it runs
in a helper thread and is *abandoned* (left running, never joined) when it does not
return in time, so the caller (the supervisor, or the main thread at exit) never hangs.

:class:`ExitGuard` makes a process exit on time even when clean-up hangs: armed on
SIGTERM/SIGINT, it flushes the logs and calls ``os._exit(0)`` after a deadline.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol, TypeVar, cast

from vibsynth.errors import DeviceError

__all__ = [
    "STARTING",
    "STREAMING",
    "LOST",
    "RECOVERING",
    "STOPPED",
    "HungCallError",
    "call_with_timeout",
    "hung_calls",
    "Backoff",
    "SupervisedStream",
    "StreamSupervisor",
    "ExitGuard",
    "flush_output",
    "hard_exit",
]

log = logging.getLogger(__name__)

T = TypeVar("T")

#: Output states (``output.state``; ``/status`` reports them as they are).
STARTING = "starting"
STREAMING = "streaming"
LOST = "device lost"
RECOVERING = "recovering"
STOPPED = "stopped"

#: A stream whose heartbeat has not moved for this long is declared lost.
HEARTBEAT_TIMEOUT_S = 0.5
#: How often the supervisor thread looks at the stream.
POLL_INTERVAL_S = 0.05
#: How long :class:`ExitGuard` waits for the logs to flush before exiting.
FLUSH_TIMEOUT_S = 0.2


class HungCallError(DeviceError):
    """A driver call did not return within its time limit; it was abandoned (still running)."""


_hung_lock = threading.Lock()
_hung: dict[int, str] = {}


def hung_calls() -> list[str]:
    """Descriptions of abandoned calls that have still not returned."""
    with _hung_lock:
        return list(_hung.values())


def call_with_timeout(fn: Callable[[], T], timeout_s: float, what: str) -> T:
    """Run ``fn()`` in a helper thread and wait at most ``timeout_s`` for it.

    Parameters
    ----------
    fn : callable
        The (possibly blocking) call.
    timeout_s : float
        Time limit.
    what : str
        What the call does, for messages ("closing the audio stream").

    Returns
    -------
    Whatever ``fn`` returns.

    Raises
    ------
    HungCallError
        ``fn`` did not return in time. Its thread (a daemon) is abandoned: nothing
        waits for it, and :func:`hung_calls` lists it until it returns, if ever.
    Exception
        Whatever ``fn`` raised.
    """
    result: list[Any] = []
    error: list[BaseException] = []
    done = threading.Event()

    def run() -> None:
        try:
            result.append(fn())
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            error.append(exc)
        finally:
            done.set()
            with _hung_lock:
                _hung.pop(threading.get_ident(), None)

    thread = threading.Thread(target=run, name=f"vibsynth-call: {what}", daemon=True)
    thread.start()
    if not done.wait(timeout_s):
        with _hung_lock:
            if not done.is_set() and thread.ident is not None:
                _hung[thread.ident] = what
        if not done.is_set():
            raise HungCallError(f"{what} did not return within {timeout_s:g} s (abandoned)")
    if error:
        raise error[0]
    return cast(T, result[0])


class Backoff:
    """Retry delays: ``first``, doubling up to ``maximum`` (0.25, 0.5, 1, 2, 2, ... s by default)."""

    def __init__(self, first: float = 0.25, maximum: float = 2.0, factor: float = 2.0) -> None:
        if not (0 < first <= maximum) or factor < 1:
            raise ValueError(f"bad back-off: first {first}, maximum {maximum}, factor {factor}")
        self.first, self.maximum, self.factor = float(first), float(maximum), float(factor)
        self._next = self.first

    def next(self) -> float:
        """The delay before the next attempt (and advance)."""
        delay = self._next
        self._next = min(self._next * self.factor, self.maximum)
        return delay

    def reset(self) -> None:
        self._next = self.first


class SupervisedStream(Protocol):
    """What :class:`StreamSupervisor` needs from an output (e.g. ``SoundDeviceOutput``)."""

    def heartbeat(self) -> int:
        """A counter the audio callback advances (blocks rendered)."""

    def stream_fault(self) -> str | None:
        """Why the current stream is not healthy (it stopped, errored), or None."""

    def drop_stream(self) -> None:
        """Get rid of the current stream in bounded time (close it, or abandon it)."""

    def reopen(self) -> str:
        """Re-scan devices, open and start a new stream (bounded time); returns its name.

        Raises DeviceError (including :class:`HungCallError`) on failure.
        """

    def housekeeping(self) -> None:
        """Called on every tick (e.g. to log callback errors)."""


class StreamSupervisor:
    """Watches a stream and brings it back after a loss, with back-off.

    :meth:`step` does one tick at a given time (tests drive it with an explicit clock);
    :meth:`start_thread` runs it every :data:`POLL_INTERVAL_S` in a daemon thread.

    Parameters
    ----------
    host : SupervisedStream
    heartbeat_timeout_s : float
        No heartbeat for this long while streaming = the device is lost.
    backoff : Backoff, optional
        Retry delays (default 0.25 s doubling to 2 s).
    clock : callable
        Monotonic seconds (``time.monotonic``).
    name : str
        What the stream is, in log messages ("audio device", "audio input device").

    Attributes
    ----------
    state : str
        :data:`STARTING`, :data:`STREAMING`, :data:`LOST`, :data:`RECOVERING` or :data:`STOPPED`.
    reason : str
        Why the device was lost (empty while streaming).
    last_error : str
        Why the last retry failed.
    attempts : int
        Retries since the loss.
    losses, recoveries : int
        Counters since start.
    lost_at, recovered_after_s : float or None
        Clock time of the last loss; how long the last recovery took.
    """

    def __init__(
        self,
        host: SupervisedStream,
        *,
        heartbeat_timeout_s: float = HEARTBEAT_TIMEOUT_S,
        backoff: Backoff | None = None,
        clock: Callable[[], float] = time.monotonic,
        poll_interval_s: float = POLL_INTERVAL_S,
        name: str = "audio device",
    ) -> None:
        self.host = host
        self.name = name
        self.heartbeat_timeout_s = float(heartbeat_timeout_s)
        self.backoff = backoff or Backoff()
        self.clock = clock
        self.poll_interval_s = float(poll_interval_s)
        self.state = STOPPED
        self.reason = ""
        self.last_error = ""
        self.attempts = 0
        self.losses = 0
        self.recoveries = 0
        self.lost_at: float | None = None
        self.recovered_after_s: float | None = None
        self.next_retry_at: float | None = None
        self._beat = 0
        self._beat_at = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- state machine -------------------------------------------------------------
    def begin(self, now: float | None = None) -> None:
        """The stream was just started: wait for its first heartbeat."""
        now = self.clock() if now is None else now
        self._stop.clear()
        self.state, self.reason, self.last_error = STARTING, "", ""
        self._beat, self._beat_at = self.host.heartbeat(), now

    def step(self, now: float | None = None) -> str:
        """One supervision tick at time ``now``; returns the state after it."""
        now = self.clock() if now is None else now
        if self.state == STOPPED or self._stop.is_set():
            return self.state
        self.host.housekeeping()
        if self.state in (STARTING, STREAMING, RECOVERING):
            self._watch(now)
        elif self.state == LOST and self.next_retry_at is not None and now >= self.next_retry_at:
            self._retry(now)
        return self.state

    def _watch(self, now: float) -> None:
        beat = self.host.heartbeat()
        if beat != self._beat:
            self._beat, self._beat_at = beat, now
            if self.state != STREAMING:
                self._streaming(now)
            return
        fault = self.host.stream_fault()
        if fault is None and now - self._beat_at > self.heartbeat_timeout_s:
            fault = f"no heartbeat for {self.heartbeat_timeout_s:g} s"
        if fault is not None:
            self._lost(fault, now)

    def _streaming(self, now: float) -> None:
        previous, self.state = self.state, STREAMING
        self.backoff.reset()
        if previous == RECOVERING and self.lost_at is not None:
            self.recovered_after_s = now - self.lost_at
            self.recoveries += 1
            log.warning(
                "%s back: streaming again after %.2f s (%d attempt(s))",
                self.name,
                self.recovered_after_s,
                self.attempts,
            )
        self.reason, self.last_error, self.attempts = "", "", 0

    def _lost(self, reason: str, now: float) -> None:
        first = self.state != RECOVERING  # a reopened stream that never beat: same outage
        self.state = LOST
        if first:
            self.reason, self.lost_at, self.attempts = reason, now, 0
            self.losses += 1
            log.warning(
                "%s lost: %s; retrying every %g-%g s (OSC/MIDI keep working)",
                self.name,
                reason,
                self.backoff.first,
                self.backoff.maximum,
            )
        else:
            self.last_error = reason
            log.info("audio retry %d failed: %s", self.attempts, reason)
        try:
            self.host.drop_stream()
        except Exception as exc:  # noqa: BLE001 - a failed close must not stop the retries
            log.info("dropping the lost stream: %s", exc)
        self.next_retry_at = now + self.backoff.next()

    def _retry(self, now: float) -> None:
        self.attempts += 1
        try:
            name = self.host.reopen()
        except Exception as exc:  # noqa: BLE001 - DeviceError mostly; anything else is a failed try too
            self.last_error = str(exc) or type(exc).__name__
            if self.attempts == 1:
                log.warning("%s still unavailable: %s", self.name, self.last_error)
            else:
                log.info("audio retry %d failed: %s", self.attempts, self.last_error)
            self.next_retry_at = self.clock() + self.backoff.next()
            return
        log.info("audio stream reopened on %s; waiting for its first blocks", name)
        self.state = RECOVERING
        self._beat, self._beat_at = self.host.heartbeat(), self.clock()
        self.next_retry_at = None

    # -- thread --------------------------------------------------------------------
    def start_thread(self) -> None:
        """Run :meth:`step` every ``poll_interval_s`` in a daemon thread."""
        if self._thread is not None and self._thread.is_alive():
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-audio-supervisor", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.poll_interval_s):
            try:
                self.step()
            except Exception as exc:  # noqa: BLE001 - the supervisor must outlive any bug in a tick
                log.error("audio supervisor: %s", exc)

    def stop(self, join_timeout_s: float = 0.3) -> None:
        """Stop supervising (state :data:`STOPPED`); waits at most ``join_timeout_s`` for the thread.

        A tick in the middle of a retry is not waited for beyond that: every call it makes
        is itself bounded, and the host refuses new streams once it is closing.
        """
        self._stop.set()
        self.state = STOPPED
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(join_timeout_s)


class ExitGuard:
    """Exit the process after a deadline if it has not exited by itself.

    Parameters
    ----------
    deadline_s : float
        Seconds after :meth:`arm`.
    exit_code : int
    exit : callable
        ``os._exit`` (injected by tests).
    """

    def __init__(self, deadline_s: float, *, exit_code: int = 0, exit: Callable[[int], Any] = os._exit) -> None:
        self.deadline_s = float(deadline_s)
        self.exit_code = int(exit_code)
        self._exit = exit
        self._armed = threading.Event()
        self._cancelled = threading.Event()
        self._thread: threading.Thread | None = None
        self.fired = False

    @property
    def armed(self) -> bool:
        return self._armed.is_set()

    def arm(self) -> None:
        """Start the countdown (idempotent; safe in a signal handler: no lock, no logging)."""
        if self._armed.is_set():
            return
        self._armed.set()
        self._thread = threading.Thread(target=self._countdown, name="vibsynth-exit-guard", daemon=True)
        self._thread.start()

    def cancel(self) -> None:
        """Stop the countdown (the process is exiting by itself)."""
        self._cancelled.set()

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait until the countdown ended (fired or cancelled); True if it did within ``timeout_s``."""
        thread = self._thread
        if thread is None:
            return False
        thread.join(timeout_s)
        return not thread.is_alive()

    def _countdown(self) -> None:
        if self._cancelled.wait(self.deadline_s):
            return
        self.fired = True
        log.warning("clean-up did not finish within %g s; exiting now", self.deadline_s)
        hard_exit(self.exit_code, exit=self._exit)


def flush_output(timeout_s: float = FLUSH_TIMEOUT_S) -> None:
    """Flush the log handlers, stdout and stderr, waiting at most ``timeout_s``.

    Flushing can block too (a full pipe, a lock held by a stuck thread), so it runs in
    a helper thread that is abandoned after the timeout.
    """

    def flush() -> None:
        try:
            for handler in logging.getLogger().handlers:
                handler.flush()
            for stream in (sys.stdout, sys.stderr):
                stream.flush()
        except Exception:  # noqa: BLE001 - exiting regardless
            pass

    flusher = threading.Thread(target=flush, name="vibsynth-exit-flush", daemon=True)
    flusher.start()
    flusher.join(timeout_s)


def hard_exit(code: int = 0, *, exit: Callable[[int], Any] = os._exit) -> None:
    """Flush the logs and end the process now (``os._exit``: no exit hooks, no C++ static destructors).

    For when a driver library is left in a state where its exit-time clean-up would
    hang or crash (e.g. libjack with a client whose server died).
    """
    flush_output()
    exit(code)
