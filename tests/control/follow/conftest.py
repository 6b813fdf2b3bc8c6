"""A real engine and controller at 16 kHz, a fake input the test writes into, and a follower on them."""

from __future__ import annotations

from typing import Any

import pytest

from tests.control.follow.fakes import FS, Rig
from vibsynth.engine.bank import BankSpec, build_bank


@pytest.fixture(scope="session")
def follow_bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, levels=9, seed=2))


@pytest.fixture
def make_rig(follow_bank, basis):
    def make(**kw: Any) -> Rig:
        return Rig(follow_bank, basis, **kw)

    return make
