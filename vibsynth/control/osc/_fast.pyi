"""Type stub of the compiled OSC receive loop (``vibsynth/control/osc/_fast.c``)."""

from collections.abc import Callable, Sequence

from vibsynth.engine._core import Core

M_INTENSITY: int
M_BALANCE: int
M_TEXTURE: int
MAX_BATCH: int

class Receiver:
    def __init__(
        self,
        fd: int,
        core: Core | None,
        table: Sequence[tuple[bytes, int, int]],
        balance_min: float,
        balance_max: float,
        on_slow: Callable[..., object],
        on_state: Callable[..., object],
        allow: Sequence[tuple[int, bytes, int]] | None,
        watch: bytearray | None = None,
    ) -> None: ...
    def run(self) -> None:
        """Receive until :meth:`stop` (returns), or until the socket fails (raises ``OSError``)."""
    def stop(self) -> None: ...
    def counters(self) -> dict[str, int]:
        """packets, bytes, fast, slow, denied, ring_full, handler_errors, recv_errors."""
