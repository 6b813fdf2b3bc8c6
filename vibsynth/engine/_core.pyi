"""Type stub of the compiled real-time core (``vibsynth/engine/_core.c``)."""

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

CMD_KNOB: int
CMD_GLIDE: int
CMD_MUTE: int
CMD_PANIC: int
CMD_LAYER: int
CMD_CANCEL: int
CMD_VOICE: int
CMD_VOICE_STOP: int
CMD_TRIM: int
LAYERS: int
TAP_FRAMES: int
MAX_CHANNELS: int
DRAIN_MAX: int
_C_API: object

class Core:
    frame: int
    applied_seq: int
    blocks: int
    underflows: int
    late_commands: int
    ring_full: int
    schedule_full: int
    callbacks: int
    pending: int
    schedule_capacity: int
    load_last: float
    load_peak: float
    load_avg: float
    def __init__(
        self,
        signals: NDArray[np.float32],
        peaks: NDArray[np.float64],
        balances_lo: float,
        balances_hi: float,
        offsets: Sequence[int],
        fs: float,
        ceiling_db: float,
        range_db: float,
        glide_s: float,
        mute_fade_s: float,
        limiter_ceiling: float,
        initial_intensity: float,
        initial_balance: float,
        max_block: int,
        ring_capacity: int,
        schedule_capacity: int,
    ) -> None: ...
    def push(
        self,
        kind: int,
        arg: int,
        value: float,
        glide: float,
        mask: int,
        at: int,
        layer: int = 0,
        ptr: int = 0,
        length: int = 0,
        /,
    ) -> int: ...
    def read_tap(self, out: NDArray[np.float32], /) -> int: ...
    def voice_ids(self) -> list[int]: ...
    def trim_values(self) -> list[tuple[float, float]]: ...
    def layers(self) -> list[int]: ...
    def render_into(self, out: NDArray[np.float32], /) -> None: ...
    def set_output_map(self, device_channels: int, columns: Sequence[int], /) -> None: ...
    def knob_values(self) -> list[tuple[float, float, bool]]: ...
    def take_peak(self) -> float: ...
    def add_underflows(self, n: int, /) -> None: ...
    def run_callback(self, out: NDArray[np.float32], status_flags: int, /) -> int: ...
    def addresses(self) -> tuple[int, int]: ...
    def output_stamp(self) -> tuple[int, float, float, float, float] | None: ...
