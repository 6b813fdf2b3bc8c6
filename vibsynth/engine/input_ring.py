"""The input ring: where an input's frames wait for the analysis, filled without the GIL.

:class:`InputRing` wraps the compiled ring (:mod:`vibsynth.engine._input`). Its producer is
the compiled PortAudio input callback (:meth:`InputRing.callback_addresses`), or the file
feeder through :meth:`InputRing.write`; its one consumer is a Python thread calling
:meth:`InputRing.read`.

* Lock-free single-producer / single-consumer hand-off (release/acquire on the two
  positions), power-of-two capacity of at least ``seconds`` of frames.
* The callback allocates nothing, takes no lock, never logs, never waits for the reader:
  with the ring full it drops the block's newest frames and counts them
  (:attr:`InputRing.dropped_frames`, :attr:`InputRing.overflows`).
* :attr:`InputRing.frames_captured` counts every frame the device delivered: while nothing
  was dropped, the ``k``-th frame read is input frame ``k``. :meth:`InputRing.stamp` and the
  output's :func:`output_stamp` put input and output frames
  on one clock (PortAudio stream time and the monotonic clock), e.g. for a loop latency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from vibsynth.engine import _input
from vibsynth.errors import ParameterError

if TYPE_CHECKING:
    from vibsynth.engine.engine import Engine

__all__ = ["InputRing", "BlockStamp", "MAX_INPUT_CHANNELS", "ring_capacity", "output_stamp", "frame_offset"]

#: Most channels a ring carries.
MAX_INPUT_CHANNELS = _input.MAX_CHANNELS

#: PortAudio status flags the callback counts.
PA_INPUT_UNDERFLOW = _input.PA_INPUT_UNDERFLOW
PA_INPUT_OVERFLOW = _input.PA_INPUT_OVERFLOW


def ring_capacity(fs: float, seconds: float) -> int:
    """The smallest power of two of frames that holds ``seconds`` at ``fs`` (at least 1024)."""
    if not (math.isfinite(fs) and fs > 0 and math.isfinite(seconds) and 0 < seconds <= 60):
        raise ParameterError(f"an input ring needs fs > 0 and 0 < seconds <= 60, got {fs!r} Hz, {seconds!r} s")
    return 1 << max(10, math.ceil(math.log2(fs * seconds)))


@dataclass(frozen=True)
class BlockStamp:
    """When a stream's last block happened, on PortAudio's clock and the monotonic clock.

    Attributes
    ----------
    frame : int
        The block's first frame (input: :attr:`InputRing.frames_captured` before it; output:
        the engine's frame position).
    adc_time, current_time, dac_time : float
        PortAudio's ``PaStreamCallbackTimeInfo`` (s, the stream's clock; 0 where the host API
        gives none): capture time of the block's first input frame, time of the callback,
        time the block's first output frame is heard.
    monotonic : float
        ``time.monotonic()`` clock (s) at the callback.
    """

    frame: int
    adc_time: float
    current_time: float
    dac_time: float
    monotonic: float

    @classmethod
    def of(cls, raw: tuple[int, float, float, float, float] | None) -> BlockStamp | None:
        return None if raw is None else cls(*raw)


class InputRing:
    """A lock-free ring of interleaved float32 input frames (see the module notes).

    Parameters
    ----------
    channels : int
        Channels of a frame (1..:data:`MAX_INPUT_CHANNELS`).
    fs : float
        Sample rate of the frames (Hz).
    seconds : float
        Least capacity (the ring holds a power of two of frames at least this long).
    """

    def __init__(self, channels: int, fs: float, *, seconds: float = 1.0) -> None:
        if int(channels) != channels or not 1 <= channels <= MAX_INPUT_CHANNELS:
            raise ParameterError(f"an input ring needs 1..{MAX_INPUT_CHANNELS} channels, got {channels!r}")
        self._ring = _input.InputRing(int(channels), ring_capacity(float(fs), float(seconds)), float(fs))

    # -- consumer -----------------------------------------------------------------------
    def read(self, max_frames: int | None = None) -> NDArray[np.float32]:
        """The oldest waiting frames, removed from the ring (never blocks).

        Parameters
        ----------
        max_frames : int, optional
            At most this many (None: all that wait).

        Returns
        -------
        frames : ndarray, shape (n, channels), float32
            ``n <= max_frames``; 0 rows when nothing waits.
        """
        waiting = self._ring.available
        if max_frames is not None:
            if int(max_frames) != max_frames or max_frames < 0:
                raise ParameterError(f"max_frames must be an integer >= 0, got {max_frames!r}")
            waiting = min(waiting, int(max_frames))
        out = np.empty((waiting, self._ring.channels), dtype=np.float32)
        got = self._ring.read_into(out)
        return out[:got]

    def skip(self, max_frames: int | None = None) -> int:
        """Drop waiting frames unread (None: all); returns how many."""
        if max_frames is not None and (int(max_frames) != max_frames or max_frames < 0):
            raise ParameterError(f"max_frames must be an integer >= 0, got {max_frames!r}")
        return self._ring.skip(-1 if max_frames is None else int(max_frames))

    # -- producers ------------------------------------------------------------------------
    def write(self, frames: NDArray[np.floating]) -> int:
        """Put frames (shape (n, device_channels)) in from Python (the file feeder); returns how many fit.

        Only while no PortAudio stream feeds this ring (a ring has one producer).
        """
        data = np.ascontiguousarray(frames, dtype=np.float32)
        if data.ndim != 2 or data.shape[1] != self._ring.device_channels:
            raise ParameterError(f"frames must have shape (n, {self._ring.device_channels}), got {data.shape}")
        return self._ring.write(data)

    def set_input_map(self, device_channels: int, columns: list[int]) -> None:
        """Which column of the device's ``device_channels`` feeds each ring channel (0-based).

        Only while no stream feeds the ring.
        """
        self._ring.set_input_map(int(device_channels), [int(c) for c in columns])

    def callback_addresses(self) -> tuple[int, int]:
        """``(PaStreamCallback address, userdata address)`` of the compiled input callback.

        The ring must outlive the stream.
        """
        return self._ring.addresses()

    def run_callback(
        self,
        block: NDArray[np.float32] | int,
        status: int = 0,
        adc_time: float = 0.0,
        current_time: float = 0.0,
        dac_time: float = 0.0,
        delay_s: float = 0.0,
    ) -> int:
        """Call the compiled PortAudio callback on a block (or on ``block`` frames of no input): tests.

        The GIL is released first, then ``delay_s`` passes before the call (a test can take the GIL meanwhile).
        """
        return self._ring.run_callback(
            block, int(status), float(adc_time), float(current_time), float(dac_time), float(delay_s)
        )

    # -- state ----------------------------------------------------------------------------
    def stamp(self) -> BlockStamp | None:
        """When the callback's last block was captured (None before the first)."""
        return BlockStamp.of(self._ring.stamp())

    def take_peaks(self) -> list[float]:
        """Each channel's largest ``|x|`` delivered since the last call (then reset)."""
        return self._ring.take_peaks()

    def take_load_peak(self) -> float:
        """The callback's peak load (time / block period) since the last call (then reset)."""
        return self._ring.take_load_peak()

    @property
    def channels(self) -> int:
        return self._ring.channels

    @property
    def device_channels(self) -> int:
        return self._ring.device_channels

    @property
    def fs(self) -> float:
        return self._ring.fs

    @property
    def capacity(self) -> int:
        """Frames the ring holds."""
        return self._ring.capacity

    @property
    def available(self) -> int:
        """Frames waiting to be read."""
        return self._ring.available

    @property
    def frames_written(self) -> int:
        """Frames put in the ring since it was made."""
        return self._ring.frames_written

    @property
    def frames_read(self) -> int:
        """Frames read or skipped since it was made."""
        return self._ring.frames_read

    @property
    def frames_captured(self) -> int:
        """Frames the device delivered (dropped ones too): the absolute input frame counter."""
        return self._ring.frames_captured

    @property
    def dropped_frames(self) -> int:
        """Frames dropped because the reader was behind (the ring was full)."""
        return self._ring.dropped_frames

    @property
    def overflows(self) -> int:
        """Blocks that dropped frames because the reader was behind."""
        return self._ring.overflows

    @property
    def input_overflows(self) -> int:
        """Blocks PortAudio flagged ``paInputOverflow`` (the driver lost input before the callback)."""
        return self._ring.input_overflows

    @property
    def input_underflows(self) -> int:
        """Blocks PortAudio flagged ``paInputUnderflow``."""
        return self._ring.input_underflows

    @property
    def callbacks(self) -> int:
        """Callbacks run (the input's heartbeat)."""
        return self._ring.callbacks

    @property
    def load_avg(self) -> float:
        """The callback's average time as a fraction of the block period."""
        return self._ring.load_avg


def output_stamp(engine: Engine) -> BlockStamp | None:
    """When the engine's PortAudio output callback last ran (None before its first block).

    ``frame`` is the engine frame position at the block's start and ``dac_time`` when that
    frame is heard, on the same PortAudio clock as an input's :meth:`InputRing.stamp`.
    """
    return BlockStamp.of(engine._core.output_stamp())


def frame_offset(output: BlockStamp, input: BlockStamp, fs: float, *, device_times: bool = True) -> float:
    """Input frame minus output frame of the same instant, from one block stamp of each stream.

    Output frame ``f`` is heard while input frame ``f + offset`` is captured; a loop (actuator
    -> sensor) that brings the output back ``D`` frames later (by cross-correlation) has its own
    latency ``D - offset``. The two stamps may come from any blocks of the two streams: they are
    put on the monotonic clock (each stream's PortAudio clock may have its own origin).

    Parameters
    ----------
    output, input : BlockStamp
        :func:`output_stamp` and :meth:`InputRing.stamp`.
    fs : float
        The rate of both streams.
    device_times : bool
        Count the driver's DAC and ADC latencies (``dac_time - current_time``, ``current_time -
        adc_time``) where the host API gives them; False: the callbacks' own times (a loop inside
        the audio server, e.g. a JACK connection from an output port to an input port).
    """
    heard = output.monotonic
    captured = input.monotonic
    if device_times and output.dac_time:
        heard += output.dac_time - output.current_time
    if device_times and input.adc_time:
        captured -= input.current_time - input.adc_time
    return float(input.frame - output.frame) + (heard - captured) * float(fs)
