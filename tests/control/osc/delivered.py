"""Waiting for the UDP receive loop's hand-over to Python (``vibsynth/control/osc/_fast.c``)."""

from __future__ import annotations

import time
from typing import Any


def wait_delivered(server: Any, timeout: float = 10.0) -> None:
    """Until Python has returned from every datagram the receive loop of ``server`` (an
    :class:`~vibsynth.control.osc.server.OscServer`) queued for it.

    A reply is sent from inside the handler: a client that answers it at once may find the handler
    not yet returned, and its datagram then queues behind (order) instead of taking the fast path.
    """
    deadline = time.monotonic() + timeout
    counters: dict[str, int] = {}
    while time.monotonic() < deadline:
        counters = server.udp.counters()
        if counters["delivered"] == counters["slow"]:
            return
        time.sleep(0.001)
    raise AssertionError(f"the receive loop's queue was not handed over in {timeout} s: {counters}")
