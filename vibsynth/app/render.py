"""The one offline renderer: a source rendered block by block into a sink, with knob moves on a timeline.

Every offline render goes through :func:`render`: ``vibsynth render`` (a texture, a
recording's variant, a MIDI file), ``vibsynth decode`` (a ``.vbt`` trajectory) and
``vibsynth preset play -o``::

    timeline of cues (frame, command)  ->  source.submit / action(at_frame)
    source.render_into(block)          ->  sink.write(block)  ->  progress(done, total)

* **Source**: the real-time :class:`~vibsynth.engine.engine.Engine` (its compiled core
  renders each block in place, exactly as the audio callback does), or a
  :class:`LoopSource` that repeats one period of a closed-form synthesis.
* **Timeline**: :class:`Cue` objects in frame order. A cue holding an engine command is
  submitted with ``at_frame`` = its frame just before the block that contains it, so the
  engine applies it at exactly that sample; a cue holding a callable is called with that
  frame (the MIDI mapper handles a message there, and its controller submits the
  commands). Commands are fed block by block, so a timeline of any length never fills
  the engine's command ring or its schedule (``knobs.schedule_capacity``).
* **Sink**: :class:`~vibsynth.formats.wav_stream.WavStreamWriter` (the file is written as
  it renders, atomically) or :class:`ArrayCollector` (an array, for callers and tests
  that want one; bounded by :data:`MAX_COLLECT_BYTES`). :func:`render` commits the sink
  (``close``) when every frame is written and discards it (``abort``) on any exception,
  Ctrl-C included: a failed render leaves no file.

Memory is one block plus the source (the engine's bank, ~38 MB at 48 kHz) whatever the
length. The output does not depend on the block size: scheduled commands land on their
exact frame, and immediate commands submitted before the render apply at frame 0.
The renderer prints nothing; ``progress(frames_done, frames_total)`` is called after
each block.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from vibsynth.engine.commands import SetGlide, SetKnob, SetMute
from vibsynth.errors import ParameterError

__all__ = [
    "Cue",
    "Source",
    "Sink",
    "RenderResult",
    "render",
    "ArrayCollector",
    "GainSink",
    "TeeSink",
    "LoopSource",
    "loop_period",
    "MAX_COLLECT_BYTES",
    "DEFAULT_BLOCK",
]

#: Frames per block when the caller does not choose (23 ms at 44.1/48 kHz).
DEFAULT_BLOCK = 1024
#: Largest array :class:`ArrayCollector` holds (256 MiB: 23 min of mono float32 at 48 kHz).
MAX_COLLECT_BYTES = 256 << 20


class Source(Protocol):
    """What :func:`render` reads from: :class:`~vibsynth.engine.engine.Engine` or :class:`LoopSource`."""

    fs: float
    channels: int

    def render_into(self, out: NDArray[Any]) -> None:
        """Fill ``out`` (shape (frames, channels), C-contiguous) with the next frames."""


class Sink(Protocol):
    """Where :func:`render` writes: ``write`` each block, then ``close`` (commit) or ``abort`` (discard)."""

    def write(self, block: NDArray[Any]) -> None:
        """Take one block, shape (frames, channels); it is reused afterwards, so copy what you keep."""

    def close(self) -> Any:
        """Commit; the return value is handed back in :attr:`RenderResult.output`."""

    def abort(self) -> None:
        """Discard everything (called on any error)."""


@dataclass(frozen=True, slots=True)
class Cue:
    """One entry of a render timeline.

    Attributes
    ----------
    frame : int
        Stream frame (0 = the first output sample) at which the action takes effect.
    action : SetKnob, SetGlide, SetMute or callable
        An engine command (submitted with ``at_frame=frame``; its own ``at_frame`` is
        ignored), or ``action(at_frame)`` called just before the block that contains
        ``frame`` (``at_frame`` is ``frame``, or the block start for a negative frame).
    """

    frame: int
    action: SetKnob | SetGlide | SetMute | Callable[[int], object]


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render` did.

    Attributes
    ----------
    frames : int
    fs : float
    channels : int
    peak : float
        Largest absolute sample of the source's output (before the sink's conversion).
    output : object
        What ``sink.close()`` returned (the path of a WAV, the array of a collector).
    """

    frames: int
    fs: float
    channels: int
    peak: float
    output: Any

    @property
    def seconds(self) -> float:
        return self.frames / self.fs


def _fire(cue: Cue, at_frame: int, source: Any) -> None:
    action = cue.action
    if isinstance(action, SetKnob | SetGlide | SetMute):
        # a command already stamped with its frame (render --follow's thousands a minute) is not copied
        source.submit(action if action.at_frame == at_frame else dataclasses.replace(action, at_frame=at_frame))
    elif callable(action):
        action(at_frame)
    else:
        raise ParameterError(f"a render cue takes SetKnob, SetGlide, SetMute or a callable, got {action!r}")


def render(
    source: Source,
    frames: int,
    sink: Sink,
    *,
    timeline: Iterable[Cue] = (),
    block: int = DEFAULT_BLOCK,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """Render ``frames`` frames of ``source`` into ``sink``, block by block, applying ``timeline``.

    Parameters
    ----------
    source : Engine or LoopSource
        A fresh engine (frame 0 = its current position; commands submitted before the
        call apply at frame 0), or any object with ``fs``, ``channels``,
        ``render_into(out)`` and, for command cues, ``submit(command)``.
    frames : int
        Output length (> 0).
    sink : Sink
        Committed with ``close()`` after the last block, ``abort()``-ed on any exception.
    timeline : iterable of Cue
        In non-decreasing frame order; consumed lazily (a generator is fine). Cues at or
        after ``frames`` are never applied.
    block : int
        Frames per block (> 0). The output does not depend on it.
    progress : callable, optional
        ``progress(frames_done, frames_total)`` after each block.

    Returns
    -------
    result : RenderResult

    Raises
    ------
    ParameterError
        Non-positive length or block, or a timeline out of order.
    """
    if int(frames) != frames or frames <= 0:
        raise ParameterError(f"render length must be a positive number of frames, got {frames!r}")
    if int(block) != block or block <= 0:
        raise ParameterError(f"block must be a positive number of frames, got {block!r}")
    frames, block = int(frames), int(block)
    try:
        dtype = np.dtype(getattr(source, "dtype", np.float32))
        buf = np.empty((min(block, frames), int(source.channels)), dtype=dtype)
        cues = iter(timeline)
        pending = next(cues, None)
        last = -math.inf
        peak = 0.0
        pos = 0
        while pos < frames:
            n = min(block, frames - pos)
            end = pos + n
            while pending is not None and pending.frame < end:
                if pending.frame < last:
                    raise ParameterError(f"render timeline out of order: frame {pending.frame} after {last}")
                last = pending.frame
                _fire(pending, max(int(pending.frame), pos), source)
                pending = next(cues, None)
            out = buf[:n]
            source.render_into(out)
            peak = max(peak, float(np.max(np.abs(out))))
            sink.write(out)
            pos = end
            if progress is not None:
                progress(pos, frames)
        output = sink.close()
    except BaseException:
        sink.abort()
        raise
    return RenderResult(frames=frames, fs=float(source.fs), channels=int(source.channels), peak=peak, output=output)


# --------------------------------------------------------------------------- sinks
class ArrayCollector:
    """Collect a short render in memory.

    Parameters
    ----------
    frames : int
        Capacity (the render's length); the array is allocated once.
    channels : int
    dtype : numpy dtype
        Of the array (the source's: float32 for the engine).
    max_bytes : int
        Refuse larger renders (default :data:`MAX_COLLECT_BYTES`): stream them to a
        file with :class:`~vibsynth.formats.wav_stream.WavStreamWriter` instead.

    Notes
    -----
    ``close()`` returns the array, shape (frames_written, channels).
    """

    def __init__(
        self, frames: int, channels: int, dtype: Any = np.float32, *, max_bytes: int = MAX_COLLECT_BYTES
    ) -> None:
        size = int(frames) * int(channels) * np.dtype(dtype).itemsize
        if size > max_bytes:
            raise ParameterError(
                f"a {size / 2**20:.0f} MiB render is too large to collect in memory "
                f"(limit {max_bytes / 2**20:.0f} MiB); write it to a WAV file instead"
            )
        self.array: NDArray[Any] | None = np.empty((int(frames), int(channels)), dtype=dtype)
        self.frames = 0

    def write(self, block: NDArray[Any]) -> None:
        if self.array is None:
            raise ValueError("the collector is closed")
        n = block.shape[0]
        if self.frames + n > self.array.shape[0]:
            raise ParameterError(f"the collector holds {self.array.shape[0]} frames; got more")
        self.array[self.frames : self.frames + n] = block
        self.frames += n

    def close(self) -> NDArray[Any]:
        if self.array is None:
            raise ValueError("the collector is closed")
        out = self.array[: self.frames]
        self.array = None
        return out

    def abort(self) -> None:
        self.array = None


class GainSink:
    """Multiply every block by ``gain`` (in float64) before handing it to ``sink``.

    Parameters
    ----------
    sink : Sink
    gain : float
    """

    def __init__(self, sink: Sink, gain: float) -> None:
        self.sink = sink
        self.gain = float(gain)

    def write(self, block: NDArray[Any]) -> None:
        self.sink.write(block.astype(np.float64) * self.gain)

    def close(self) -> Any:
        return self.sink.close()

    def abort(self) -> None:
        self.sink.abort()


class TeeSink:
    """Hand every block to several sinks; ``close`` returns their results as a tuple."""

    def __init__(self, *sinks: Sink) -> None:
        self.sinks = sinks

    def write(self, block: NDArray[Any]) -> None:
        for sink in self.sinks:
            sink.write(block)

    def close(self) -> tuple[Any, ...]:
        results = []
        try:
            for sink in self.sinks:
                results.append(sink.close())
        except BaseException:
            for sink in self.sinks[len(results) :]:
                sink.abort()
            raise
        return tuple(results)

    def abort(self) -> None:
        for sink in self.sinks:
            sink.abort()


# --------------------------------------------------------------------------- loop source
class LoopSource:
    """Repeat one period of a signal: the source of closed-form syntheses (``vibsynth render``).

    Parameters
    ----------
    period : ndarray, shape (n,) or (n, channels)
        One period of a seamless loop; kept in its dtype (float64 for the DSP core), so
        the sink converts exactly as it would convert the whole signal.
    fs : float
    """

    def __init__(self, period: NDArray[Any], fs: float) -> None:
        data = np.asarray(period)
        if data.ndim == 1:
            data = data[:, np.newaxis]
        if data.ndim != 2 or data.shape[0] == 0:
            raise ParameterError(f"a loop needs a non-empty (frames, channels) period, got shape {np.shape(period)}")
        self.period = np.ascontiguousarray(data)
        self.fs = float(fs)
        self.channels = int(data.shape[1])
        self.dtype = data.dtype
        self.peak = float(np.max(np.abs(data)))
        self._pos = 0

    def render_into(self, out: NDArray[Any]) -> None:
        """Fill ``out`` (shape (frames, channels)) with the next frames of the loop."""
        n, size, done = out.shape[0], self.period.shape[0], 0
        while done < n:
            take = min(n - done, size - self._pos)
            out[done : done + take] = self.period[self._pos : self._pos + take]
            done += take
            self._pos = (self._pos + take) % size


def loop_period(frames: int, max_frames: int) -> int:
    """The period to synthesise for a seamless loop of ``frames`` frames, at most ``max_frames`` long.

    ``frames`` itself when it fits (the output is then one period, as before streaming);
    otherwise the longest period in [max_frames / 2, max_frames] that divides ``frames``,
    so the file is a whole number of periods and still loops seamlessly. If no such
    divisor exists (e.g. a prime length), ``max_frames``: the file then loops seamlessly
    only at multiples of the period.

    Parameters
    ----------
    frames, max_frames : int

    Returns
    -------
    period : int
    """
    if frames <= max_frames:
        return int(frames)
    first = -(-frames // max_frames)
    for k in range(first, 2 * first + 1):
        if frames % k == 0:
            return frames // k
    return int(max_frames)
