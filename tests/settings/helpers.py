"""Helpers of the settings tests: watching a library reload, editing files as an editor does."""

from __future__ import annotations

import os
import threading
from pathlib import Path


class Recorder:
    """An ``on_change`` callback of a library watcher that remembers the names it was called with."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.event = threading.Event()

    def __call__(self, name: str) -> None:
        self.calls.append(name)
        self.event.set()

    def wait(self, timeout: float = 1.0) -> list[str]:
        """The names seen since the last wait (at least one within ``timeout``)."""
        assert self.event.wait(timeout), f"no change picked up within {timeout:g} s"
        self.event.clear()
        calls, self.calls = self.calls, []
        return calls


def edit(path: Path, text: str) -> None:
    """Write in place (not atomic, like many editors) and make sure the mtime moves."""
    old = path.stat().st_mtime_ns if path.exists() else 0
    path.write_text(text)
    if path.stat().st_mtime_ns == old:
        os.utime(path, ns=(old + 1_000_000, old + 1_000_000))
