"""Type stub of the compiled OSC receive loop (``vibsynth/control/osc/_fast.c``)."""

from collections.abc import Callable, Sequence

from vibsynth.engine._core import Core

M_INTENSITY: int
M_BALANCE: int
M_TEXTURE: int
MAX_BATCH: int
QUEUE_MAX: int

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
        """Receive until :meth:`stop` (returns), or until the socket fails (raises ``OSError``);
        never takes the GIL meanwhile."""
    def deliver(self, timeout_s: float, /) -> bool:
        """Hand what :meth:`run` queued for Python over (``on_state``, then ``on_slow``), waiting up
        to ``timeout_s`` (0..3600) for it; False once :meth:`run` has returned and nothing is left."""
    def stop(self) -> None: ...
    def counters(self) -> dict[str, int]:
        """packets, bytes, fast, slow (queued for Python), delivered (handed over, Python has returned),
        denied, ring_full, queue_full, handler_errors, recv_errors."""
