"""A fake input source (a real InputRing the test writes into), seeded test signals, and the rig of a
real engine + controller + follower on it, stepped by hand."""

from __future__ import annotations

from typing import Any

import numpy as np

from vibsynth.control.controller import Controller
from vibsynth.control.follow.follower import Follower
from vibsynth.engine.engine import Engine
from vibsynth.engine.input_ring import InputRing
from vibsynth.settings.models_config import VibsynthConfig

#: The rig's rate (a small bank builds fast).
FS = 16000.0


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


class Rig:
    """Engine + controller + fake input + follower, stepped by hand: ``feed(x)`` writes, tracks and renders."""

    def __init__(self, bank, basis, *, channels: int = 2, inputs: int = 1, follow: dict[str, Any] | None = None):
        self.settings = VibsynthConfig.model_validate(
            {"audio": {"channels": channels}, "follow": {"enabled": True, **(follow or {})}}
        )
        self.engine = Engine(bank, channels=channels, glide_s=0.0, max_block=256)
        self.controller = Controller(self.engine, initial_glide_s=0.0)
        self.source = FakeInput(inputs, FS)
        self.clock = Clock()
        self.follower = Follower(
            self.controller, self.source, self.settings.follow, knobs=self.settings.knobs, basis=basis, clock=self.clock
        )
        self.source.open()
        self.follower.prepare()

    def feed(self, x, block: int = 128) -> None:
        """Write ``x`` (n,) or (n, inputs) a block at a time; after each, one step and one rendered block."""
        for i in range(0, len(x), block):
            self.source.write(x[i : i + block])
            self.follower.step()
            self.engine.render(block)
            self.clock.t += block / FS

    def idle(self, seconds: float, block: int = 128) -> None:
        """Time passes with no input (steps and renders)."""
        for _ in range(int(seconds * FS / block)):
            self.follower.step()
            self.engine.render(block)
            self.clock.t += block / FS

    def plays(self, channel: int) -> tuple[float, float]:
        k, b, _ = self.engine.knob_values()[channel]
        return k, b
