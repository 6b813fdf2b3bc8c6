"""A fake input source (a real InputRing the test writes into) and seeded test signals."""

from __future__ import annotations

from typing import Any

import numpy as np

from vibsynth.engine.input_ring import InputRing


class FakeInput:
    """An :class:`~vibsynth.engine.inputs.InputSource` whose frames the test writes; its state is set by the test."""

    def __init__(self, channels: int, fs: float) -> None:
        self.ring = InputRing(channels, fs, seconds=4.0)
        self.fs = fs
        self.state = "closed"
        self.reason = ""
        self.opened = 0

    def open(self) -> None:
        self.opened += 1
        self.state = "open"

    def close(self) -> None:
        self.state = "closed"

    def status(self) -> dict[str, Any]:
        return {"device": "fake input", "state": self.state, "reason": self.reason, "level_db": -20.0, "overflows": 0}

    def write(self, x: np.ndarray) -> None:
        x = np.asarray(x, dtype=np.float32)
        self.ring.write(x[:, None] if x.ndim == 1 else x)


class Clock:
    """A monotonic clock the test moves."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def tone(fs: float, seconds: float, rms: float, hz: float = 140.0, start: int = 0) -> np.ndarray:
    """A sine of the given RMS (its 80-200 Hz band level is 20 log10(rms) dB)."""
    n = int(round(seconds * fs))
    t = (start + np.arange(n)) / fs
    return (np.sqrt(2.0) * rms * np.sin(2 * np.pi * hz * t)).astype(np.float64)
