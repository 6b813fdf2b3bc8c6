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
  buffer. Underflows are counted in C from the callback's status flags. A watchdog
  thread restarts the stream (with back-off) when the device errors or the stream
  stops by itself.
* :class:`NullOutput`: paced by ``time.monotonic`` in its own thread, for machines
  without a sound card (the engine keeps its timing, controls keep working).
* :class:`WavOutput`: renders a fixed duration as fast as possible into a WAV file.

``sounddevice`` is imported lazily (:func:`import_sounddevice`), so machines
without PortAudio can still use the other backends; its ``OSError`` becomes a
:class:`~vibsynth.errors.DeviceError`.
"""
from __future__ import annotations

import logging
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Sequence

import numpy as np

from vibsynth.engine.engine import Engine
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
        return self._engine.stats.callbacks

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

    def _count_underflow(self) -> None:
        self.stats.underflows += 1
        self.engine.stats.underflows = self.stats.underflows


# ---------------------------------------------------------------------- sounddevice
def import_sounddevice() -> ModuleType:
    """Import python-sounddevice, turning a missing PortAudio into :class:`DeviceError`."""
    try:
        import sounddevice
    except OSError as exc:  # the PortAudio shared library is missing
        raise DeviceError(f"PortAudio is not available ({exc}); install libportaudio2") from None
    except ImportError as exc:
        raise DeviceError(f"python-sounddevice is not installed ({exc})") from None
    return sounddevice


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


def resolve_device(sd: ModuleType, device: str | int | None, host_api: str | int | None = None) -> int:
    """Index of the output device chosen by index, name substring and/or host API.

    Raises
    ------
    DeviceError
        No output device at all, or none (or several) matching.
    """
    devices = sd.query_devices()
    api = _host_api_index(sd, host_api)
    outputs = [
        i for i, d in enumerate(devices)
        if d["max_output_channels"] > 0 and (api is None or d["hostapi"] == api)
    ]
    where = f" on host API {sd.query_hostapis(api)['name']!r}" if api is not None else ""
    if not outputs:
        raise DeviceError(f"no audio output device found{where}")
    if device is None or device == "":
        if api is not None:
            default = sd.query_hostapis(api)["default_output_device"]
        else:
            default = sd.default.device[1]
        if isinstance(default, (int, np.integer)) and default in outputs:
            return int(default)
        return outputs[0]
    if isinstance(device, (int, np.integer)) or str(device).strip().isdigit():
        index = int(device)
        if index not in outputs:
            raise DeviceError(f"device {index} is not an output device{where} (see `vibsynth devices`)")
        return index
    wanted = str(device).lower()
    matches = [i for i in outputs if wanted in devices[i]["name"].lower()]
    exact = [i for i in matches if devices[i]["name"].lower() == wanted]
    if exact:
        return exact[0]
    if not matches:
        raise DeviceError(f"no output device matches {device!r}{where} (see `vibsynth devices`)")
    if len(matches) > 1:
        names = "; ".join(f"{i}: {devices[i]['name']}" for i in matches)
        raise DeviceError(f"device {device!r} is ambiguous ({names}); give an index or a longer name")
    return matches[0]


def list_devices() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Host APIs and output devices (as dicts); raises DeviceError without PortAudio."""
    sd = import_sounddevice()
    apis = [dict(a, index=i) for i, a in enumerate(sd.query_hostapis())]
    devices = [dict(d, index=i) for i, d in enumerate(sd.query_devices()) if d["max_output_channels"] > 0]
    return apis, devices


class SoundDeviceOutput(OutputBackend):
    """PortAudio callback stream.

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
        Reopen the stream when it errors or stops by itself.
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
    ) -> None:
        super().__init__(engine)
        self.device = device
        self.host_api = host_api
        self.block_size = int(block_size)
        self.latency = latency
        mapping = list(channel_map) if channel_map else list(range(1, engine.channels + 1))
        if len(mapping) != engine.channels or any(int(m) < 1 for m in mapping) or len(set(mapping)) != len(mapping):
            raise ParameterError(
                f"channel_map must list {engine.channels} distinct device outputs (1-based), got {channel_map!r}"
            )
        self.channel_map = [int(m) - 1 for m in mapping]
        self.device_channels = max(self.channel_map) + 1
        self.stats = CallbackStats(engine)  # type: ignore[assignment]
        self.restart = restart
        self._sd: ModuleType | None = None
        self._stream: Any = None
        self._device_index: int | None = None
        self._want_running = False
        self._failed = False
        self._watchdog: threading.Thread | None = None
        self._stop_event = threading.Event()
        self.last_error: BaseException | None = None

    def _finished(self) -> None:
        if self._want_running:
            self._failed = True

    # -- life cycle ---------------------------------------------------------------
    def open(self) -> None:
        """Open (not start) the stream: after this the device ports exist (JACK tests connect here)."""
        if self._stream is not None:
            return
        sd = self._sd or import_sounddevice()
        self._sd = sd
        index = resolve_device(sd, self.device, self.host_api)
        info = sd.query_devices(index)
        if info["max_output_channels"] < self.device_channels:
            raise DeviceError(
                f"device {info['name']!r} has {info['max_output_channels']} outputs; "
                f"the channel map needs {self.device_channels}"
            )
        try:
            self._stream = self._open_stream(sd, index)
        except Exception as exc:  # sd.PortAudioError, ValueError for bad settings
            raise DeviceError(f"cannot open {info['name']!r} at {self.engine.fs:g} Hz: {exc}") from None
        self._device_index = index
        self._failed = False

    def _open_stream(self, sd: ModuleType, index: int) -> Any:
        """A PortAudio output stream whose callback is the engine's compiled one (no GIL)."""
        callback, userdata = self.engine.callback_addresses()
        self.engine.set_output_map(self.device_channels, self.channel_map)
        return sd._StreamBase(
            kind="output", samplerate=self.engine.fs, blocksize=self.block_size, device=index,
            channels=self.device_channels, dtype="float32", latency=self.latency,
            callback=sd._ffi.cast("PaStreamCallback *", callback), userdata=sd._ffi.cast("void *", userdata),
            finished_callback=self._finished,
        )

    def start(self) -> None:
        self.open()
        self._want_running = True
        try:
            self._stream.start()
        except Exception as exc:
            raise DeviceError(f"cannot start the audio stream: {exc}") from None
        if self.restart and self._watchdog is None:
            self._stop_event.clear()
            self._watchdog = threading.Thread(target=self._watch, name="vibsynth-audio-watchdog", daemon=True)
            self._watchdog.start()

    def _close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.abort() if self._failed else stream.stop()
            except Exception:
                pass
            try:
                stream.close()
            except Exception:
                pass

    def stop(self) -> None:
        self._want_running = False
        self._stop_event.set()
        if self._watchdog is not None:
            self._watchdog.join(timeout=5)
            self._watchdog = None
        self._close()

    def is_running(self) -> bool:
        return self._stream is not None and bool(self._stream.active)

    def _watch(self) -> None:
        backoff = 0.5
        reported_errors = 0
        while not self._stop_event.wait(0.25):
            if self.stats.errors != reported_errors:
                reported_errors = self.stats.errors
                log.error("audio callback error (block filled with silence): %r", self.last_error)
            stream = self._stream
            if not self._want_running or (stream is not None and not self._failed and stream.active):
                backoff = 0.5
                continue
            log.warning("audio stream stopped unexpectedly; restarting in %.1f s", backoff)
            if self._stop_event.wait(backoff):
                return
            self._close()
            try:
                self.open()
                self._stream.start()
                self.stats.restarts += 1
                self.engine.stats.output_errors += 1
                log.warning("audio stream restarted on device %s", self._device_index)
            except Exception as exc:
                self._failed = True
                log.warning("audio restart failed: %s", exc)
                backoff = min(backoff * 2, 10.0)

    def describe(self) -> str:
        name = "?"
        if self._sd is not None and self._device_index is not None:
            info = self._sd.query_devices(self._device_index)
            api = self._sd.query_hostapis(info["hostapi"])["name"]
            name = f"{info['name']} ({api})"
        latency = getattr(self._stream, "latency", None)
        lat = f", latency {1000 * latency:.1f} ms" if isinstance(latency, float) else ""
        return (f"sounddevice: {name}, {self.engine.fs:g} Hz, block {self.block_size}{lat}, "
                f"outputs {[c + 1 for c in self.channel_map]}")


# ---------------------------------------------------------------------- null
class NullOutput(OutputBackend):
    """Renders blocks in real time (monotonic clock) and discards them.

    A block more than ``max_lag_s`` late counts as an underflow and the clock resyncs.
    """

    name = "null"

    def __init__(self, engine: Engine, *, block_size: int = 128, max_lag_s: float = 0.05) -> None:
        super().__init__(engine)
        if block_size < 1:
            raise ParameterError(f"block size must be >= 1, got {block_size}")
        self.block_size = int(block_size)
        self.max_lag_s = float(max_lag_s)
        self._buffer = np.zeros((self.block_size, engine.channels), dtype=np.float32)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_block: np.ndarray = self._buffer

    def _run(self) -> None:
        period = self.block_size / self.engine.fs
        next_t = time.monotonic()
        while not self._stop.is_set():
            self.engine.render_into(self._buffer)
            self.stats.callbacks += 1
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif -delay > self.max_lag_s:
                self._count_underflow()
                next_t = time.monotonic()

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
    """Renders ``seconds`` of output as fast as possible and writes a float32 WAV file.

    The file is written (atomically) when rendering finishes or :meth:`stop` is called.
    """

    name = "wav"

    def __init__(self, engine: Engine, path: str | Path, *, seconds: float, block_size: int = 1024) -> None:
        super().__init__(engine)
        if not (seconds > 0) or seconds != seconds or seconds == float("inf"):
            raise ParameterError(f"wav output needs a finite duration > 0 s, got {seconds!r}")
        self.path = Path(path)
        self.frames = int(round(seconds * engine.fs))
        self.block_size = int(block_size)
        self._data = np.zeros((self.frames, engine.channels), dtype=np.float32)
        self._done = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.written = threading.Event()

    def _run(self) -> None:
        while self._done < self.frames and not self._stop.is_set():
            n = min(self.block_size, self.frames - self._done)
            self.engine.render_into(self._data[self._done:self._done + n])
            self._done += n
            self.stats.callbacks += 1
        self._write()

    def _write(self) -> None:
        from vibsynth.io import write_wav

        try:
            write_wav(self.path, self._data[: self._done], self.engine.fs)
        except OSError as exc:
            log.error("cannot write %s: %s", self.path, exc)
        self.written.set()

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="vibsynth-wav-output", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def is_running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def describe(self) -> str:
        return f"wav file {self.path} ({self.frames / self.engine.fs:g} s at {self.engine.fs:g} Hz, faster than real time)"
