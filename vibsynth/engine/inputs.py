"""Input sources: where Follow's (and calibration's) signal comes from, into an :class:`InputRing`.

A small protocol, :class:`InputSource` (``open()`` / ``close()`` / ``ring`` / ``status()``), so
the control layer reads any of them the same way:

* :class:`SoundDeviceInput`: a PortAudio input stream whose callback is the compiled one of
  the ring (no GIL, no allocation, no lock, no log), on a device spec ``DEVICE[:CH,...]``.
  Supervised like the output (:class:`~vibsynth.engine.pa_stream.PortAudioStream`): a device
  that vanishes is reported (``status()["state"]`` ``lost``, then ``retrying``) and reopened
  when it comes back, in the same PortAudio instance as the output (on JACK, the same JACK
  client: its ``in_N`` ports stand beside the output's ``out_N``).
* :class:`FileInput`: a sound file (WAV, FLAC, Ogg, MP3...; any channels, any rate, resampled to the engine's rate block
  by block, never loaded whole) fed into a ring by a Python thread, paced by the *output*
  clock (the engine's frame position), looping or ending.

* :class:`~vibsynth.engine.monitor.MonitorInput`: what the system plays (``--follow monitor``).

:func:`vibsynth.engine.sources.open_input` picks one from a ``--follow`` argument.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import numpy as np

from vibsynth.engine import outputs
from vibsynth.engine.input_ring import MAX_INPUT_CHANNELS, InputRing
from vibsynth.engine.outputs import resolve_device
from vibsynth.engine.pa_stream import PortAudioStream
from vibsynth.engine.supervisor import HEARTBEAT_TIMEOUT_S, LOST, RECOVERING, STARTING, STREAMING, Backoff
from vibsynth.errors import DeviceError, InputError, ParameterError

__all__ = [
    "InputSource",
    "InputSpec",
    "SoundDeviceInput",
    "FileInput",
    "parse_input_spec",
    "level_db",
]

log = logging.getLogger(__name__)

#: Input states (``status()["state"]``).
OPEN = "open"
STARTING_STATE = "starting"
LOST_STATE = "lost"
RETRYING = "retrying"
CLOSED = "closed"
ENDED = "ended"

#: Level reported for silence (dBFS).
SILENCE_DB = -120.0
#: A peak meter read more often than this returns the last reading (several readers share it).
METER_REFRESH_S = 0.05

_CHANNELS = re.compile(r"^\s*\d+\s*(,\s*\d+\s*)*$")


def level_db(peak: float) -> float:
    """A peak (linear, full scale 1) in dBFS, :data:`SILENCE_DB` at the bottom."""
    return SILENCE_DB if not peak > 10 ** (SILENCE_DB / 20) else round(20.0 * math.log10(peak), 2)


@dataclass(frozen=True)
class InputSpec:
    """A parsed ``DEVICE[:CH,...]``.

    Attributes
    ----------
    device : str or int or None
        Name substring or index; None = the default input.
    channels : tuple of int or None
        1-based device inputs, in ring order; None = the device's first two (or only) inputs.
    text : str
        As given.
    """

    device: str | int | None
    channels: tuple[int, ...] | None
    text: str


def parse_input_spec(spec: str | None) -> InputSpec:
    """Parse ``DEVICE[:CH,...]`` (``"system:1,2"``, ``"3"``, ``"USB mic:2"``, ``""`` = default).

    The part after the last ``:`` is a channel list only when it is a list of numbers; a device
    whose name ends in such a list (``"hw:1,0"``) is still found whole (see
    :meth:`SoundDeviceInput._resolve`).

    Raises
    ------
    ParameterError
        Channel 0, a repeated channel, or more than :data:`MAX_INPUT_CHANNELS`.
    """
    text = "" if spec is None else str(spec)
    head, sep, tail = text.rpartition(":")
    channels: tuple[int, ...] | None = None
    device_text = text
    if sep and _CHANNELS.match(tail):
        channels = tuple(int(c) for c in tail.split(","))
        device_text = head
        if any(c < 1 for c in channels):
            raise ParameterError(f"input {text!r}: channels are numbered from 1, got {list(channels)}")
        if len(set(channels)) != len(channels):
            raise ParameterError(f"input {text!r}: channel listed twice in {list(channels)}")
        if len(channels) > MAX_INPUT_CHANNELS:
            raise ParameterError(f"input {text!r}: at most {MAX_INPUT_CHANNELS} channels, got {len(channels)}")
    device_text = device_text.strip()
    device: str | int | None = int(device_text) if device_text.isdigit() else (device_text or None)
    return InputSpec(device, channels, text)


class InputSource(Protocol):
    """What the control layer needs of an input (a device or a file)."""

    @property
    def ring(self) -> InputRing:
        """The ring the frames arrive in (valid after :meth:`open`, kept across reopens)."""

    @property
    def fs(self) -> float:
        """Rate of the frames (the engine's)."""

    def open(self) -> None:
        """Start delivering frames into :attr:`ring` (raises DeviceError / InputError)."""

    def close(self) -> None:
        """Stop (bounded time); the ring stays readable."""

    def status(self) -> dict[str, Any]:
        """``device``, ``state`` (open, starting, lost, retrying, ended, closed), ``reason``, counters, levels."""


class _Meter:
    """Per-channel peaks taken from the ring at most every :data:`METER_REFRESH_S` (shared by readers)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._at = -math.inf
        self._peaks: list[float] = []

    def peaks(self, ring: InputRing | None) -> list[float]:
        if ring is None:
            return []
        now = self.clock()
        if now - self._at >= METER_REFRESH_S or len(self._peaks) != ring.channels:
            self._peaks, self._at = ring.take_peaks(), now
        return self._peaks


def _ring_status(ring: InputRing | None, meter: _Meter) -> dict[str, Any]:
    """The counters and levels every input reports."""
    peaks = meter.peaks(ring)
    if ring is None:
        return {
            "overflows": 0,
            "dropped_frames": 0,
            "input_overflows": 0,
            "frames": 0,
            "level_peak": [],
            "level_db": SILENCE_DB,
        }
    return {
        "overflows": ring.overflows,
        "dropped_frames": ring.dropped_frames,
        "input_overflows": ring.input_overflows,
        "frames": ring.frames_captured,
        "level_peak": [round(p, 6) for p in peaks],
        "level_db": level_db(max(peaks, default=0.0)),
    }


# ---------------------------------------------------------------------- device
class SoundDeviceInput(PortAudioStream):
    """A supervised PortAudio input stream into an :class:`InputRing` (see the module notes).

    Parameters
    ----------
    spec : str or None
        ``DEVICE[:CH,...]``: a name substring or index, then 1-based inputs (default: the
        first two, or the only one).
    fs : float
        Rate of the stream (the engine's).
    host_api : str, int or None
    block_size : int
        Frames per callback (0 = PortAudio chooses).
    latency : {"low", "high"} or float
    seconds : float
        Least ring capacity.
    restart, heartbeat_timeout_s, backoff, clock
        As for :class:`~vibsynth.engine.outputs.SoundDeviceOutput`.

    Raises
    ------
    ParameterError
        A malformed spec (at construction). Device problems (no such device, a channel it
        lacks, a rate it refuses) are :class:`DeviceError` at :meth:`open`.
    """

    def __init__(
        self,
        spec: str | None,
        *,
        fs: float,
        host_api: str | int | None = None,
        block_size: int = 128,
        latency: str | float = "low",
        seconds: float = 1.0,
        restart: bool = True,
        heartbeat_timeout_s: float = HEARTBEAT_TIMEOUT_S,
        backoff: Backoff | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.spec = parse_input_spec(spec)
        if not (math.isfinite(fs) and fs > 0):
            raise ParameterError(f"an input needs a rate > 0, got {fs!r}")
        self._fs = float(fs)
        self.seconds = float(seconds)
        self.channels: tuple[int, ...] | None = self.spec.channels
        self._ring: InputRing | None = None
        self._meter = _Meter()
        super().__init__(
            "input",
            device=self.spec.device,
            host_api=host_api,
            block_size=block_size,
            latency=latency,
            restart=restart,
            heartbeat_timeout_s=heartbeat_timeout_s,
            backoff=backoff,
            clock=clock,
        )

    def _import_sounddevice(self) -> ModuleType:
        return outputs.import_sounddevice()  # the output's, so one stand-in serves both in tests

    @property
    def fs(self) -> float:
        return self._fs

    @property
    def ring(self) -> InputRing:
        if self._ring is None:
            raise DeviceError(f"input {self.spec.text!r} is not open yet")
        return self._ring

    # -- stream creation ---------------------------------------------------------------
    def _resolve(self, sd: ModuleType) -> int:
        """The device index; a name ending in a number list (``hw:1,0``) is tried whole too."""
        try:
            return resolve_device(sd, self.spec.device, self.host_api, kind="input")
        except DeviceError:
            if self.spec.channels is None or not self.spec.text.strip():
                raise
            try:
                index = resolve_device(sd, self.spec.text.strip(), self.host_api, kind="input")
            except DeviceError:
                pass
            else:
                self.device, self.channels = self.spec.text.strip(), None
                return index
            raise

    def _create_stream(self) -> Any:
        sd = self._sd
        assert sd is not None
        index = self._resolve(sd)
        info = sd.query_devices(index)
        available = int(info["max_input_channels"])
        channels = self.channels or tuple(range(1, min(available, 2) + 1))
        missing = [c for c in channels if c > available]
        if missing:
            raise DeviceError(
                f"input device {info['name']!r} has {available} input{'s' if available != 1 else ''} "
                f"(channels 1..{available}); {', '.join(map(str, missing))} "
                f"{'does' if len(missing) == 1 else 'do'} not exist"
            )
        if self._ring is None:
            self._ring = InputRing(len(channels), self._fs, seconds=self.seconds)
        elif self._ring.channels != len(channels):  # the first open fixed them; unreachable
            raise DeviceError(f"input {self.spec.text!r} changed its channel count")
        self.channels = channels
        device_channels = max(channels)
        self._ring.set_input_map(device_channels, [c - 1 for c in channels])
        callback, userdata = self._ring.callback_addresses()
        try:
            stream = sd._StreamBase(
                kind="input",
                samplerate=self._fs,
                blocksize=self.block_size,
                device=index,
                channels=device_channels,
                dtype="float32",
                latency=self.latency,
                callback=sd._ffi.cast("PaStreamCallback *", callback),
                userdata=sd._ffi.cast("void *", userdata),
                finished_callback=self._finished,
            )
        except Exception as exc:  # sd.PortAudioError, ValueError for bad settings
            raise DeviceError(f"cannot open input {info['name']!r} at {self._fs:g} Hz: {exc}") from None
        self._device_index = index
        return stream

    def heartbeat(self) -> int:
        return 0 if self._ring is None else self._ring.callbacks

    # -- InputSource ---------------------------------------------------------------------
    def open(self) -> None:
        """Open and start the stream, supervised (a loss is then retried in the background)."""
        self.start()

    def open_ports(self) -> None:
        """Open without starting: the JACK ports exist (connect them), no frame flows yet."""
        self._open()

    def close(self) -> None:
        self.stop()

    def describe(self) -> str:
        chans = list(self.channels) if self.channels else "default"
        return f"input {self._device_label()}, channels {chans}, {self._fs:g} Hz, block {self.block_size}"

    def status(self) -> dict[str, Any]:
        sup = self.supervisor
        state = {
            STREAMING: OPEN,
            STARTING: STARTING_STATE,
            RECOVERING: RETRYING,
            LOST: RETRYING if sup.attempts else LOST_STATE,
        }.get(sup.state, CLOSED)
        label = self._device_label() if self._device_index is not None else (self.spec.text or "default")
        return {
            "kind": "device",
            "device": label,
            "channels": list(self.channels or ()),
            "state": state,
            "reason": sup.reason,
            "last_error": sup.last_error,
            "restarts": self.restarts,
            "recovered_after_s": sup.recovered_after_s,
            "callback_load": 0.0 if self._ring is None else round(self._ring.load_avg, 5),
            **_ring_status(self._ring, self._meter),
        }


# ---------------------------------------------------------------------- file
class FileInput:
    """A sound file played into an :class:`InputRing`, paced by the output's frame clock.

    A Python thread (never the audio thread) reads the file block by block
    (:func:`~vibsynth.formats.sound_reader.open_sound`: WAV, FLAC, Ogg, MP3...), resamples it to ``fs``
    (:class:`~vibsynth.dsp.resample_stream.StreamResampler`, equal to ``resample_poly``) and
    writes it into the ring so that ``lead_frames`` more frames are in than output frames
    rendered since :meth:`open`: the file plays in step with the output, whatever the
    machine's clock does. Memory stays at a few blocks whatever the file's length.

    Parameters
    ----------
    path : path-like
        A sound file (1..64 channels, 1 kHz..768 kHz).
    fs : float
        The engine's rate.
    frame_clock : callable
        Frames the output has rendered (``engine.frame_position``).
    channels : sequence of int, optional
        1-based file channels, in ring order (default: all).
    loop : bool
        Start again at the end (gap-free) instead of ending.
    lead_frames : int
        Frames the file runs ahead of the output clock (absorbs the feeder's wake-up jitter).
    block_frames : int
        Frames read from the file at a time.
    seconds : float
        Least ring capacity.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        fs: float,
        frame_clock: Callable[[], int],
        channels: Sequence[int] | None = None,
        loop: bool = False,
        lead_frames: int = 512,
        block_frames: int = 1024,
        seconds: float = 1.0,
    ) -> None:
        from vibsynth.formats.sound_reader import open_sound

        self.path = Path(path)
        if not (math.isfinite(fs) and fs > 0):
            raise ParameterError(f"an input needs a rate > 0, got {fs!r}")
        self._fs = float(fs)
        self.frame_clock = frame_clock
        self.loop = bool(loop)
        with open_sound(self.path) as reader:  # header checked now: a bad file is one clear error
            self.file_fs, self.file_channels, self.file_frames = reader.fs, reader.channels, reader.frames
        picked = list(channels) if channels else list(range(1, self.file_channels + 1))
        bad = [c for c in picked if int(c) != c or not 1 <= c <= self.file_channels]
        if bad or len(set(picked)) != len(picked) or len(picked) > MAX_INPUT_CHANNELS:
            raise InputError(
                f"{self.path}: has {self.file_channels} channel{'s' if self.file_channels != 1 else ''} "
                f"(1..{self.file_channels}); cannot take channels {list(channels or [])}"
            )
        self.channels = tuple(int(c) for c in picked)
        if int(lead_frames) != lead_frames or lead_frames < 0 or int(block_frames) != block_frames or block_frames < 1:
            raise ParameterError(f"lead_frames must be >= 0 and block_frames >= 1, got {lead_frames}, {block_frames}")
        self.lead_frames, self.block_frames = int(lead_frames), int(block_frames)
        self._ring = InputRing(len(self.channels), self._fs, seconds=seconds)
        self._meter = _Meter()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.ended = threading.Event()
        #: The output frame at which the file's first frame was due (None until it starts).
        self.start_frame: int | None = None
        self.loops = 0
        self.error: str = ""
        self._state = CLOSED

    @property
    def ring(self) -> InputRing:
        return self._ring

    @property
    def fs(self) -> float:
        return self._fs

    @property
    def duration_s(self) -> float:
        return self.file_frames / self.file_fs

    def open(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self.ended.clear()
        self.start_frame = None
        self._state = OPEN
        self._thread = threading.Thread(target=self._run, name="vibsynth-file-input", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=5)
        if self._state == OPEN:
            self._state = CLOSED

    def _blocks(self) -> Any:
        """Resampled (frames, channels) float32 blocks of the file, looping if asked."""
        from vibsynth.dsp.resample_stream import StreamResampler
        from vibsynth.formats.sound_reader import open_sound

        columns = [c - 1 for c in self.channels]
        resampler = StreamResampler(self.file_fs, self._fs, len(columns))
        while True:
            with open_sound(self.path) as reader:
                for block in reader.blocks(self.block_frames):
                    out = resampler.process(block[:, columns])
                    if out.shape[0]:
                        yield out.astype(np.float32)
            if not self.loop or self._stop.is_set():
                break
            self.loops += 1  # the next pass follows gap-free through the same resampler
        tail = resampler.flush()
        if tail.shape[0]:
            yield tail.astype(np.float32)

    def _run(self) -> None:
        start = self.start_frame = int(self.frame_clock())
        fed = 0
        pending = np.zeros((0, len(self.channels)), dtype=np.float32)
        blocks = self._blocks()
        poll = min(0.005, 0.5 * self.block_frames / self._fs)
        try:
            while not self._stop.is_set():
                due = int(self.frame_clock()) - start + self.lead_frames
                while fed < due and not self._stop.is_set():
                    if pending.shape[0] == 0:
                        pending = next(blocks)
                    n = min(due - fed, pending.shape[0])
                    self._ring.write(pending[:n])
                    pending, fed = pending[n:], fed + n
                self._stop.wait(poll)
        except StopIteration:
            self._state = ENDED
            self.ended.set()
        except (InputError, OSError) as exc:
            self.error = str(exc)
            self._state = ENDED
            self.ended.set()
            log.warning("follow file input stopped: %s", exc)

    def status(self) -> dict[str, Any]:
        return {
            "kind": "file",
            "device": str(self.path),
            "channels": list(self.channels),
            "state": self._state,
            "reason": self.error,
            "loops": self.loops,
            "duration_s": round(self.duration_s, 3),
            "position_s": round(self._ring.frames_captured / self._fs, 3),
            **_ring_status(self._ring, self._meter),
        }
