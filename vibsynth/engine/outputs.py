"""Output backends: where the engine's blocks go.

A small interface (like mido's ports) so tests and the service swap them freely:

``start()`` / ``stop()`` / ``is_running()`` / ``describe()`` and a ``stats``
(:class:`OutputStats`) object.

* :class:`SoundDeviceOutput`: a PortAudio callback stream (python-sounddevice). The
  callback is the engine's compiled C callback (:meth:`Engine.callback_addresses`),
  handed to PortAudio through sounddevice's ``_StreamBase(callback=<C pointer>,
  userdata=...)`` hook (the one ``rtmixer`` uses): it renders straight into
  PortAudio's interleaved buffer with the channel map, never calls into Python (no
  GIL), allocates nothing, takes no lock, never logs and always fills the whole
  buffer. Underflows are counted in C from the callback's status flags. A
  supervisor thread (:mod:`vibsynth.engine.supervisor`) detects a lost device (stream
  stopped, JACK server gone, no heartbeat) and reopens it with back-off; ``state`` and
  ``state_reason`` say what is going on.
* :class:`NullOutput`: paced by ``time.monotonic`` in its own thread, for machines
  without a sound card (the engine keeps its timing, controls keep working).
* :class:`WavOutput`: renders a fixed duration as fast as possible into a WAV file.

``sounddevice`` is imported lazily (:func:`import_sounddevice`), so machines
without PortAudio can still use the other backends; its ``OSError`` becomes a
:class:`~vibsynth.errors.DeviceError`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from vibsynth.engine.engine import Engine
from vibsynth.engine.pa_stream import PortAudioStream, import_sounddevice
from vibsynth.engine.supervisor import HEARTBEAT_TIMEOUT_S, STOPPED, STREAMING, Backoff
from vibsynth.errors import DeviceError, ParameterError

__all__ = [
    "OutputStats",
    "OutputBackend",
    "SoundDeviceOutput",
    "NullOutput",
    "WavOutput",
    "import_sounddevice",
    "resolve_device",
    "list_devices",
]

log = logging.getLogger(__name__)


@dataclass
class OutputStats:
    """Counters of an output (plain attributes; written by the audio thread, read by anyone).

    Attributes
    ----------
    callbacks : int
        Blocks delivered.
    underflows : int
        Output underflows reported by the driver (or late blocks of the null clock).
    restarts : int
        Times the stream was reopened after an error.
    errors : int
        Exceptions caught in the callback (the block was filled with zeros).
    """

    callbacks: int = 0
    underflows: int = 0
    restarts: int = 0
    errors: int = 0


class CallbackStats:
    """:class:`OutputStats` of the compiled callback: its counters live in the engine's core."""

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self.restarts = 0
        self.errors = 0

    @property
    def callbacks(self) -> int:
        return int(self._engine.stats.callbacks)

    @property
    def underflows(self) -> int:
        return self._engine.stats.underflows


class OutputBackend:
    """Base class of outputs; subclasses implement :meth:`start`, :meth:`stop`, :meth:`is_running`."""

    name = "output"

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.stats = OutputStats()

    def start(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def is_running(self) -> bool:
        raise NotImplementedError

    def describe(self) -> str:
        """One line for the start-up banner."""
        return self.name

    @property
    def state(self) -> str:
        """``streaming`` or ``stopped`` (a device output adds ``device lost`` and others)."""
        return STREAMING if self.is_running() else STOPPED

    @property
    def state_reason(self) -> str:
        """Why the output is not streaming ("" when it is)."""
        return ""

    def _count_underflow(self) -> None:
        self.stats.underflows += 1
        self.engine.stats.count_underflow()


# ---------------------------------------------------------------------- sounddevice
def _host_api_index(sd: ModuleType, host_api: str | int | None) -> int | None:
    if host_api is None:
        return None
    apis = sd.query_hostapis()
    if isinstance(host_api, int) or str(host_api).isdigit():
        i = int(host_api)
        if 0 <= i < len(apis):
            return i
    else:
        for i, api in enumerate(apis):
            if str(host_api).lower() in api["name"].lower():
                return i
    names = ", ".join(a["name"] for a in apis) or "none"
    raise DeviceError(f"no host API matches {host_api!r} (available: {names})")


def resolve_device(
    sd: ModuleType, device: str | int | None, host_api: str | int | None = None, *, kind: str = "output"
) -> int:
    """Index of the ``kind`` (output or input) device chosen by index, name substring and/or host API.

    Raises
    ------
    DeviceError
        No such device at all, or none (or several) matching.
    """
    devices = sd.query_devices()
    api = _host_api_index(sd, host_api)
    key = f"max_{kind}_channels"
    found = [i for i, d in enumerate(devices) if d.get(key, 0) > 0 and (api is None or d["hostapi"] == api)]
    where = f" on host API {sd.query_hostapis(api)['name']!r}" if api is not None else ""
    if not found:
        raise DeviceError(f"no audio {kind} device found{where}")
    if device is None or device == "":
        if api is not None:
            default = sd.query_hostapis(api).get(f"default_{kind}_device", -1)
        else:
            default = sd.default.device[1 if kind == "output" else 0]
        if isinstance(default, (int, np.integer)) and default in found:
            return int(default)
        return found[0]
    if isinstance(device, (int, np.integer)) or str(device).strip().isdigit():
        index = int(device)
        if index not in found:
            raise DeviceError(f"device {index} is not an {kind} device{where} (see `vibsynth devices`)")
        return index
    wanted = str(device).lower()
    matches = [i for i in found if wanted in devices[i]["name"].lower()]
    exact = [i for i in matches if devices[i]["name"].lower() == wanted]
    if exact:
        return exact[0]
    if not matches:
        raise DeviceError(f"no {kind} device matches {device!r}{where} (see `vibsynth devices`)")
    if len(matches) > 1:
        names = "; ".join(f"{i}: {devices[i]['name']}" for i in matches)
        raise DeviceError(f"device {device!r} is ambiguous ({names}); give an index or a longer name")
    return matches[0]


def list_devices(kind: str = "output") -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Host APIs and the ``kind`` (output or input) devices (as dicts); raises DeviceError without PortAudio."""
    sd = import_sounddevice()
    apis = [dict(a, index=i) for i, a in enumerate(sd.query_hostapis())]
    devices = [dict(d, index=i) for i, d in enumerate(sd.query_devices()) if d.get(f"max_{kind}_channels", 0) > 0]
    return apis, devices


class SoundDeviceOutput(PortAudioStream, OutputBackend):
    """PortAudio callback stream, supervised: a lost device is retried until it comes back.

    Streams are created in one place, :meth:`_open_stream`. A
    :class:`~vibsynth.engine.supervisor.StreamSupervisor` thread watches the engine's
    heartbeat (``engine.stats.blocks``, advanced by the compiled callback) and the
    stream's health; after a loss it drops the stream, re-scans PortAudio
    (:class:`~vibsynth.engine.pa_runtime.PortAudioRuntime`, shared with a device input) and
    reopens with back-off. The engine object is kept, so the knobs are unchanged. Every
    PortAudio call that may block is bounded in time and abandoned if it hangs. The life
    cycle is :class:`~vibsynth.engine.pa_stream.PortAudioStream`'s.

    Parameters
    ----------
    engine : Engine
    device : str, int or None
        Name substring or index; None = the (host API's) default output.
    host_api : str, int or None
    block_size : int
        Frames per callback (0 = let PortAudio choose, variable).
    latency : {"low", "high"} or float
    channel_map : sequence of int, optional
        1-based device output for each engine channel; None = 1..channels.
    restart : bool
        Run the supervisor thread (reopen after a loss). False: call
        ``supervisor.step()`` yourself (tests).
    heartbeat_timeout_s : float
        No new block for this long while streaming = device lost.
    backoff : Backoff, optional
        Retry delays (default 0.25 s doubling to 2 s).
    clock : callable
        Monotonic clock of the supervisor.

    Attributes
    ----------
    state : str
        ``starting``, ``streaming``, ``device lost``, ``recovering`` or ``stopped``.
    state_reason : str
        Why the device was lost ("JACK server shut down", "stream stopped",
        "no heartbeat for 0.5 s"); empty while streaming.
    """

    name = "sounddevice"

    def __init__(
        self,
        engine: Engine,
        *,
        device: str | int | None = None,
        host_api: str | int | None = None,
        block_size: int = 128,
        latency: str | float = "low",
        channel_map: Sequence[int] | None = None,
        restart: bool = True,
        heartbeat_timeout_s: float = HEARTBEAT_TIMEOUT_S,
        backoff: Backoff | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        OutputBackend.__init__(self, engine)
        mapping = list(channel_map) if channel_map else list(range(1, engine.channels + 1))
        if len(mapping) != engine.channels or any(int(m) < 1 for m in mapping) or len(set(mapping)) != len(mapping):
            raise ParameterError(
                f"channel_map must list {engine.channels} distinct device outputs (1-based), got {channel_map!r}"
            )
        self.channel_map = [int(m) - 1 for m in mapping]
        self.device_channels = max(self.channel_map) + 1
        self.stats = CallbackStats(engine)  # type: ignore[assignment]
        self._reported_errors = 0
        self.last_error: BaseException | None = None
        PortAudioStream.__init__(
            self,
            "output",
            device=device,
            host_api=host_api,
            block_size=block_size,
            latency=latency,
            restart=restart,
            heartbeat_timeout_s=heartbeat_timeout_s,
            backoff=backoff,
            clock=clock,
        )

    def _import_sounddevice(self) -> ModuleType:
        return import_sounddevice()  # looked up here, so tests can stand in a fake PortAudio

    # -- stream creation ---------------------------------------------------------------
    def _create_stream(self) -> Any:
        """Resolve the device and open (not start) a stream on it; runs with a time limit.

        Raises
        ------
        DeviceError
            No such device, too few outputs, or PortAudio refused the settings.
        """
        sd = self._sd
        assert sd is not None
        index = resolve_device(sd, self.device, self.host_api)
        info = sd.query_devices(index)
        if info["max_output_channels"] < self.device_channels:
            raise DeviceError(
                f"device {info['name']!r} has {info['max_output_channels']} outputs; "
                f"the channel map needs {self.device_channels}"
            )
        try:
            stream = self._open_stream(sd, index)
        except Exception as exc:  # sd.PortAudioError, ValueError for bad settings
            raise DeviceError(f"cannot open {info['name']!r} at {self.engine.fs:g} Hz: {exc}") from None
        self._device_index = index
        return stream

    def _open_stream(self, sd: ModuleType, index: int) -> Any:
        """A PortAudio output stream whose callback is the engine's compiled one (no GIL)."""
        callback, userdata = self.engine.callback_addresses()
        self.engine.set_output_map(self.device_channels, self.channel_map)
        return sd._StreamBase(
            kind="output",
            samplerate=self.engine.fs,
            blocksize=self.block_size,
            device=index,
            channels=self.device_channels,
            dtype="float32",
            latency=self.latency,
            callback=sd._ffi.cast("PaStreamCallback *", callback),
            userdata=sd._ffi.cast("void *", userdata),
            finished_callback=self._finished,
        )

    # -- what the supervisor calls (SupervisedStream) -------------------------------
    def heartbeat(self) -> int:
        return int(self.engine.stats.blocks)

    def _recovered(self) -> None:
        self.stats.restarts += 1
        self.engine.stats.output_errors += 1

    def housekeeping(self) -> None:
        errors = self.stats.errors
        if errors != self._reported_errors:
            self._reported_errors = errors
            log.error("audio callback error (block filled with silence): %r", self.last_error)

    # -- description ------------------------------------------------------------------
    def describe(self) -> str:
        latency = getattr(self._stream, "latency", None)
        lat = f", latency {1000 * latency:.1f} ms" if isinstance(latency, float) else ""
        return (
            f"sounddevice: {self._device_label()}, {self.engine.fs:g} Hz, block {self.block_size}{lat}, "
            f"outputs {[c + 1 for c in self.channel_map]}"
        )


# ---------------------------------------------------------------------- null
class NullOutput(OutputBackend):
    """Renders blocks in real time (monotonic clock) and discards them.

    A block more than ``max_lag_s`` late counts as an underflow and the clock resyncs.

    Parameters
    ----------
    engine : Engine
    block_size : int
        Frames per block.
    max_lag_s : float
        Lateness that counts as an underflow.
    clock : callable
        Monotonic seconds (default :func:`time.monotonic`; tests pass a fake clock and
        call :meth:`step` themselves).
    """

    name = "null"

    def __init__(
        self,
        engine: Engine,
        *,
        block_size: int = 128,
        max_lag_s: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(engine)
        if block_size < 1:
            raise ParameterError(f"block size must be >= 1, got {block_size}")
        self.block_size = int(block_size)
        self.max_lag_s = float(max_lag_s)
        self.clock = clock
        self._buffer = np.zeros((self.block_size, engine.channels), dtype=np.float32)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._next_t: float | None = None
        self.last_block: np.ndarray = self._buffer

    def step(self) -> float:
        """Render one block and schedule the next one a block period later.

        Returns
        -------
        delay : float
            Seconds until the next block is due (<= 0: due now). A block more than
            ``max_lag_s`` late counts as an underflow and the schedule restarts from now.
        """
        if self._next_t is None:
            self._next_t = self.clock()
        self.engine.render_into(self._buffer)
        self.stats.callbacks += 1
        self._next_t += self.block_size / self.engine.fs
        now = self.clock()
        delay = self._next_t - now
        if -delay > self.max_lag_s:
            self._count_underflow()
            self._next_t = now
        return delay

    def _run(self) -> None:
        self._next_t = None
        while not self._stop.is_set():
            delay = self.step()
            if delay > 0:
                self._stop.wait(delay)

    def start(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="vibsynth-null-output", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None

    def is_running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def describe(self) -> str:
        return f"null output (no sound card): {self.engine.fs:g} Hz, block {self.block_size}, paced by the system clock"


# ---------------------------------------------------------------------- wav
class WavOutput(OutputBackend):
    """Renders ``seconds`` of output as fast as possible into a float32 WAV file, streamed.

    The file is written block by block by a
    :class:`~vibsynth.formats.wav_stream.WavStreamWriter` (memory: one block, whatever
    the duration) and committed atomically when rendering finishes or :meth:`stop` is
    called (then it holds what was rendered so far). Stopped before :meth:`start`,
    nothing is written.

    Parameters
    ----------
    engine : Engine
    path : path-like
        The WAV file. Its folder must exist and be writable: checked here, before any
        rendering.
    seconds : float
        Duration (finite, > 0).
    block_size : int
        Frames rendered per block.

    Raises
    ------
    ParameterError
        A bad duration.
    OSError
        The file cannot be created (missing or read-only folder, a folder at ``path``);
        ``filename`` names the culprit.

    Notes
    -----
    A write that fails while rendering (disk full, the folder removed, the target
    turned into a folder) leaves no file; it is kept in :attr:`error` and raised by
    :meth:`stop`, so that ``vibsynth serve`` exits non-zero.
    """

    name = "wav"

    def __init__(self, engine: Engine, path: str | Path, *, seconds: float, block_size: int = 1024) -> None:
        from vibsynth.formats.wav_stream import WavStreamWriter

        super().__init__(engine)
        if not (seconds > 0) or seconds != seconds or seconds == float("inf"):
            raise ParameterError(f"wav output needs a finite duration > 0 s, got {seconds!r}")
        if int(block_size) != block_size or block_size <= 0:
            raise ParameterError(f"wav output needs a block size > 0 frames, got {block_size!r}")
        self.path = Path(path)
        self.frames = int(round(seconds * engine.fs))
        self.block_size = int(block_size)
        self._writer = WavStreamWriter(self.path, engine.fs, engine.channels, frames=self.frames)
        self._block = np.zeros((min(self.block_size, self.frames), engine.channels), dtype=np.float32)
        self._done = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: Set once the file is committed, or given up on (see :attr:`error`).
        self.written = threading.Event()
        #: Why the file could not be written (raised once by :meth:`stop`), else None.
        self.error: OSError | None = None

    @property
    def frames_done(self) -> int:
        """Frames rendered and handed to the file so far."""
        return self._done

    def _run(self) -> None:
        try:
            while self._done < self.frames and not self._stop.is_set():
                n = min(self.block_size, self.frames - self._done)
                block = self._block[:n]
                self.engine.render_into(block)
                self._writer.write(block)
                self._done += n
                self.stats.callbacks += 1
            self._writer.close()
        except OSError as exc:
            self._writer.abort()
            self.error = exc
            log.debug("cannot write %s: %s", self.path, exc)
        except BaseException:
            self._writer.abort()
            raise
        finally:
            self.written.set()

    def start(self) -> None:
        if self._thread is None and not self._writer.closed:
            self._thread = threading.Thread(target=self._run, name="vibsynth-wav-output", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop rendering and commit what was rendered (nothing if never started).

        Raises
        ------
        OSError
            The file could not be written (once; nothing is left behind).
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        elif not self._writer.closed:  # never started: no file
            self._writer.abort()
            self.written.set()
        error, self.error = self.error, None
        if error is not None:
            raise error

    def is_running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def describe(self) -> str:
        return (
            f"wav file {self.path} ({self.frames / self.engine.fs:g} s at {self.engine.fs:g} Hz, faster than real time)"
        )
