"""A real engine and controller at 16 kHz, a fake input the test writes into, and a follower on them."""

from __future__ import annotations

from typing import Any

import pytest

from tests.control.follow.fakes import Clock, FakeInput
from vibsynth.control.controller import Controller
from vibsynth.control.follow.follower import Follower
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.settings.models_config import VibsynthConfig

FS = 16000.0


@pytest.fixture(scope="session")
def follow_bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, levels=9, seed=2))


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


@pytest.fixture
def make_rig(follow_bank, basis):
    def make(**kw: Any) -> Rig:
        return Rig(follow_bank, basis, **kw)

    return make
