"""Type stub of the compiled input ring (``vibsynth/engine/_input.c``)."""

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

MAX_CHANNELS: int
PA_INPUT_UNDERFLOW: int
PA_INPUT_OVERFLOW: int

class InputRing:
    channels: int
    device_channels: int
    capacity: int
    fs: float
    available: int
    frames_written: int
    frames_read: int
    frames_captured: int
    dropped_frames: int
    overflows: int
    input_overflows: int
    input_underflows: int
    callbacks: int
    load_last: float
    load_peak: float
    load_avg: float
    def __init__(self, channels: int, capacity: int, fs: float) -> None: ...
    def set_input_map(self, device_channels: int, columns: Sequence[int], /) -> None: ...
    def read_into(self, out: NDArray[np.float32], /) -> int: ...
    def skip(self, frames: int, /) -> int: ...
    def write(self, frames: NDArray[np.float32], /) -> int: ...
    def run_callback(
        self,
        block: NDArray[np.float32] | int,
        status: int = 0,
        adc: float = 0.0,
        current: float = 0.0,
        dac: float = 0.0,
        delay: float = 0.0,
        /,
    ) -> int: ...
    def addresses(self) -> tuple[int, int]: ...
    def stamp(self) -> tuple[int, float, float, float, float] | None: ...
    def take_peaks(self) -> list[float]: ...
    def take_load_peak(self) -> float: ...
