"""Stream clock: OSC timetags (NTP time) -> engine stream frames."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class StreamClock:
    """Maps wall time (``time.time()``) to the engine's stream position (frames).

    The engine publishes ``frame_position`` in whole blocks, after rendering each one at the
    start of its audio cycle: at that moment the block it just rendered, which starts one
    block *before* ``frame_position``, begins to play. So the frame playing at a wall time is
    estimated from ``(frame_position - block)/fs - wall`` (``block``: the engine's
    ``max_block``, the output's callback size when serving; without it the offset would put
    every timetagged command one block late). One such sample is late by up to a block more
    (it may be taken later in the cycle); the estimate keeps the largest (least late) offset
    seen, decaying slowly (``drift`` s/s, 1000 ppm: more than sound cards and JACK's dummy
    driver drift) so that the drift between the audio clock and
    the system clock is followed, and resets when the stream jumps (restart). A sample taken
    before the stream has rendered its first block only stands in until the stream runs. The
    OSC handler samples it with every batch of packets it receives.
    """

    def __init__(
        self, engine: Any, *, drift: float = 1e-3, reset_s: float = 0.25, wall: Callable[[], float] = time.time
    ) -> None:
        self.engine = engine
        self.lead_frames = int(getattr(engine, "max_block", 0) or 0)
        self.drift = drift
        self.reset_s = reset_s
        self.wall = wall
        self._offset: float | None = None
        self._provisional = False
        self._last_wall = 0.0

    def sample(self) -> tuple[int, float]:
        """Read the engine clock once; return ``(frame_position, wall_time)``."""
        frame = int(self.engine.frame_position)
        now = self.wall()
        offset = (frame - self.lead_frames) / float(self.engine.fs) - now
        est = self._offset
        if frame <= 0:
            # No block rendered yet (the stream has not started, or has just restarted): frame 0
            # plays when the stream starts, not now, so this offset is too large by the wait. It is
            # the best guess until a sample of the running stream replaces it, never kept as the
            # largest: that put every timetag late by the wait (0.1-0.3 s after a slow start),
            # for minutes at the drift's pace.
            est, self._provisional = offset, True
        elif est is None or self._provisional:
            est, self._provisional = offset, False
        else:
            est -= self.drift * max(0.0, now - self._last_wall)
            if offset > est or offset < est - self.reset_s:
                est = offset
        self._offset = est
        self._last_wall = now
        return frame, now

    def frame_at(self, unix_time: float) -> tuple[int, int]:
        """Stream frame for a wall time; returns ``(frame, current_frame_position)``."""
        current, _ = self.sample()
        assert self._offset is not None
        return int(round((unix_time + self._offset) * float(self.engine.fs))), current
