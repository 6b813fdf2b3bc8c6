"""A supervised PortAudio stream of either direction: what the device output and input share.

:class:`PortAudioStream` owns one PortAudio stream whose callback is compiled C (the engine's
output callback, or the input ring's), its life cycle (open, start, stop) and its recovery
after a device loss, driven by a :class:`~vibsynth.engine.supervisor.StreamSupervisor`.
Subclasses say how to open the stream (:meth:`PortAudioStream._create_stream`) and what their
heartbeat is.

Every stream of a process shares one :class:`~vibsynth.engine.pa_runtime.PortAudioRuntime`
(:func:`~vibsynth.engine.pa_runtime.shared_runtime`), so a JACK server that dies under the
output and the input is re-scanned once, and a re-scan (``Pa_Terminate``) never runs under a
stream that still plays: the runtime asks every attached stream (:meth:`stream_alive`) first.
Opening and re-scanning happen under the runtime's lock, so the output's and the input's
supervisors never interleave them. A stream opened before the last re-scan is never called
again (the re-scan closed it, or it lives in a retired library instance).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from types import ModuleType
from typing import Any

from vibsynth.engine.pa_runtime import PortAudioRuntime, shared_runtime
from vibsynth.engine.supervisor import HEARTBEAT_TIMEOUT_S, Backoff, HungCallError, StreamSupervisor
from vibsynth.errors import DeviceError

__all__ = ["PortAudioStream", "import_sounddevice"]

log = logging.getLogger(__name__)


def import_sounddevice() -> ModuleType:
    """Import python-sounddevice (a dependency), turning a missing PortAudio into :class:`DeviceError`.

    Raises
    ------
    DeviceError
        The PortAudio shared library is missing (sounddevice raises OSError: its Linux wheels use
        the system's libportaudio2), or the sounddevice package itself (an install without
        dependencies): one line saying what to install.
    """
    try:
        import sounddevice
    except OSError as exc:  # the PortAudio shared library is missing
        raise DeviceError(f"PortAudio is not available ({exc}); install libportaudio2") from None
    except ImportError as exc:  # installed with --no-deps, or removed
        raise DeviceError(f"the sounddevice package is not installed ({exc}); pip install sounddevice") from None
    module: ModuleType = sounddevice
    return module


class PortAudioStream:
    """One supervised PortAudio stream (see the module notes).

    Parameters
    ----------
    kind : {"output", "input"}
        Used in messages.
    device : str, int or None
        Name substring or index; None = the (host API's) default device.
    host_api : str, int or None
    block_size : int
        Frames per callback (0 = let PortAudio choose, variable).
    latency : {"low", "high"} or float
    restart : bool
        Run the supervisor thread (reopen after a loss). False: call ``supervisor.step()``
        yourself (tests).
    heartbeat_timeout_s : float
    backoff : Backoff, optional
    clock : callable
        Monotonic clock of the supervisor.
    """

    def __init__(
        self,
        kind: str,
        *,
        device: str | int | None,
        host_api: str | int | None,
        block_size: int,
        latency: str | float,
        restart: bool,
        heartbeat_timeout_s: float = HEARTBEAT_TIMEOUT_S,
        backoff: Backoff | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.kind = kind
        self._noun = "" if kind == "output" else f"{kind} "  # "the audio stream" stays the output's
        self.device = device
        self.host_api = host_api
        self.block_size = int(block_size)
        self.latency = latency
        self.restart = restart
        self._sd: ModuleType | None = None
        self._runtime: PortAudioRuntime | None = None
        self._stream: Any = None
        self._epoch = -1  # the runtime's re-scan count when the stream was opened
        self._device_index: int | None = None
        self._on_jack = False
        self._want_running = False
        self._failed = False
        self._started = False  # the current stream was started (so inactive = it stopped by itself)
        self._closing = False
        self._lock = threading.Lock()
        self.restarts = 0
        self.supervisor = StreamSupervisor(
            self,
            heartbeat_timeout_s=heartbeat_timeout_s,
            backoff=backoff,
            clock=clock,
            name=f"audio {self._noun}device",
        )

    # -- what subclasses provide -----------------------------------------------------
    def _create_stream(self) -> Any:
        """Resolve the device, check it, open (not start) the stream; sets ``_device_index``.

        Runs with a time limit, under the runtime's lock. Raises DeviceError.
        """
        raise NotImplementedError

    def heartbeat(self) -> int:
        """A counter the compiled callback advances."""
        raise NotImplementedError

    def _recovered(self) -> None:
        """A lost stream was reopened and started (count it)."""
        self.restarts += 1

    def housekeeping(self) -> None:
        """Called on every supervisor tick."""

    # -- shared ------------------------------------------------------------------------
    def _finished(self) -> None:
        if self._want_running:
            self._failed = True

    def _import_sounddevice(self) -> ModuleType:
        return import_sounddevice()

    def _portaudio(self) -> PortAudioRuntime:
        if self._sd is None:
            self._sd = self._import_sounddevice()
        if self._runtime is None:
            self._runtime = shared_runtime(self._sd)
            self._runtime.attach(self)
        return self._runtime

    @property
    def runtime(self) -> PortAudioRuntime:
        """The PortAudio instance this stream lives in (shared by every stream of the process)."""
        return self._portaudio()

    def _new_stream(self) -> Any:
        """:meth:`_create_stream` with a time limit; notes whether the device is on JACK."""
        runtime = self._portaudio()
        stream = runtime.call(self._create_stream, f"opening the audio {self._noun}device")
        self._epoch = runtime.epoch
        self._on_jack = "jack" in self._host_api_name().lower()
        return stream

    def _host_api_name(self) -> str:
        try:
            sd: Any = self._sd
            return str(sd.query_hostapis(sd.query_devices(self._device_index)["hostapi"])["name"])
        except Exception:  # noqa: BLE001 - informative only
            return ""

    def open(self) -> None:
        """Open (not start) the stream: after this the device ports exist (JACK tests connect here)."""
        self._open()

    def _open(self) -> None:
        if self._stream is not None:
            return
        runtime = self._portaudio()
        with runtime.lock:
            stream = self._new_stream()
            with self._lock:
                self._stream, self._failed, self._started = stream, False, False

    def start(self) -> None:
        self._open()
        self._want_running, self._closing = True, False
        try:
            self._portaudio().call(self._stream.start, f"starting the audio {self._noun}stream")
        except Exception as exc:
            raise DeviceError(f"cannot start the audio {self._noun}stream: {exc}") from None
        self._started = True
        self.supervisor.begin()
        if self.restart:
            self.supervisor.start_thread()

    def stop(self) -> None:
        """Stop supervising, then stop and close the stream; returns within about 1.3 s whatever happens."""
        self._want_running = False
        with self._lock:
            self._closing = True
            stream, self._stream = self._stream, None
        self.supervisor.stop()
        if stream is not None and self._runtime is not None:
            if self._epoch != self._runtime.epoch:
                self._runtime.forget(stream)
                return
            fault = self._fault_of(stream) if self._started else None
            dead = self._on_jack and fault is not None
            if not self._runtime.close(stream, dead=dead, graceful=fault is None) and self._on_jack:
                self._runtime.mark_dirty(f"its JACK {self._noun}stream did not close")

    def shutdown_portaudio(self) -> bool:
        """At process exit, after :meth:`stop`: terminate PortAudio if that is safe.

        Returns False when PortAudio could not be terminated cleanly (after a device
        loss, or a hung call): the process should then end with
        :func:`~vibsynth.engine.supervisor.hard_exit`. See :meth:`PortAudioRuntime.shutdown`.
        """
        return True if self._runtime is None else self._runtime.shutdown()

    def is_running(self) -> bool:
        stream = self._stream
        if stream is None or (self._runtime is not None and self._epoch != self._runtime.epoch):
            return False
        try:
            return bool(stream.active)
        except Exception:  # noqa: BLE001 - a PortAudio error: not running
            return False

    @property
    def state(self) -> str:
        return self.supervisor.state

    @property
    def state_reason(self) -> str:
        return self.supervisor.reason

    # -- what the supervisor and the runtime call ----------------------------------------
    def _fault_of(self, stream: Any) -> str | None:
        if stream is None:
            return "no stream"
        if self._runtime is not None and self._epoch != self._runtime.epoch:
            return "PortAudio was re-initialised"  # never call a stream of an earlier scan
        try:
            active = bool(stream.active) and not self._failed
        except Exception as exc:  # noqa: BLE001 - sd.PortAudioError
            return f"PortAudio error: {exc}"
        if active:
            return None
        # PortAudio's JACK host API marks its streams inactive when the server goes away
        # (it calls no finished callback); elsewhere the stream ends by itself.
        return "JACK server shut down" if self._on_jack else "stream stopped"

    def stream_fault(self) -> str | None:
        return self._fault_of(self._stream)

    def stream_alive(self) -> bool:
        """Whether this stream holds a healthy stream (a re-scan now would kill it); under the runtime's lock."""
        stream = self._stream
        if stream is None:
            return False
        return not self._started or self._fault_of(stream) is None

    def drop_stream(self) -> None:
        with self._lock:
            stream, self._stream = self._stream, None
        if stream is None or self._runtime is None:
            return
        if self._epoch != self._runtime.epoch:
            self._runtime.forget(stream)
            return
        # A JACK stream that went inactive by itself: its server is gone and any call on it
        # would wait 10 min (then abort the process); never call it again.
        dead = self._on_jack and self._started and self._fault_of(stream) is not None
        self._runtime.close(stream, dead=dead)
        if self._on_jack:
            self._runtime.mark_dirty(f"its JACK {self._noun}stream was lost")

    def reopen(self) -> str:
        runtime = self._portaudio()
        with runtime.lock:
            return self._reopen(runtime)

    def _reopen(self, runtime: PortAudioRuntime) -> str:
        if self._closing:
            raise DeviceError(f"the {self.kind} is closing")
        runtime.reinitialize()
        try:
            stream = self._new_stream()
        except HungCallError:
            raise
        except DeviceError:
            self._settle()
            raise
        with self._lock:
            closing = self._closing
            if not closing:
                self._stream, self._failed, self._started = stream, False, False
        if closing:
            runtime.close(stream, dead=False)
            raise DeviceError(f"the {self.kind} is closing")
        try:
            runtime.call(stream.start, f"starting the audio {self._noun}stream")
        except HungCallError:
            with self._lock:
                if self._stream is stream:
                    self._stream = None
            runtime.abandon(stream, "starting a stream hung")
            raise
        except Exception as exc:
            self.drop_stream()
            self._settle()
            raise DeviceError(f"cannot start the audio {self._noun}stream: {exc}") from None
        self._started = True
        self._recovered()
        return self._device_label()

    def _settle(self) -> None:
        """After a failed attempt: terminate PortAudio now, while its servers were just seen alive.

        The runtime skips it while another stream plays on the instance.
        """
        try:
            self._runtime.terminate()  # type: ignore[union-attr]
        except DeviceError as exc:
            log.info("terminating PortAudio after a failed retry: %s", exc)

    def _device_label(self) -> str:
        try:
            info = self._sd.query_devices(self._device_index)  # type: ignore[union-attr]
            return f"{info['name']} ({self._host_api_name()})"
        except Exception:  # noqa: BLE001 - informative only
            return "?"
