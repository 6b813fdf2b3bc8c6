"""A callback run on the studio's loop at a fixed period while at least one page is open."""

from __future__ import annotations

import asyncio
from collections.abc import Callable


class WhilePagesOpen:
    """Call ``tick()`` at once when the first page opens, then every ``period_s``, until the last closes.

    Feed it the studio's page counts (``server.on_pages_changed(ticker.pages_changed)``); it runs
    on the studio's loop, so ``tick`` must not block.

    Parameters
    ----------
    period_s : float
    tick : callable
    """

    def __init__(self, period_s: float, tick: Callable[[], None]) -> None:
        self.period_s = period_s
        self.tick = tick
        self._timer: asyncio.TimerHandle | None = None

    def pages_changed(self, pages: int) -> None:
        if pages and self._timer is None:
            self._run()
        elif not pages and self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _run(self) -> None:
        self.tick()
        self._timer = asyncio.get_running_loop().call_later(self.period_s, self._run)
