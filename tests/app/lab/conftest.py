"""Fixtures of the lab's app tests: a real engine (small bank, rendered offline) and sessions of renders."""

from __future__ import annotations

import pytest

from tests.engine.conftest import SMALL_SPEC

RATE = SMALL_SPEC.fs


@pytest.fixture(scope="session")
def small_bank(basis):
    from vibsynth.engine.bank import build_bank

    return build_bank(basis, SMALL_SPEC)


@pytest.fixture
def engine(small_bank):
    """One channel, texture at intensity 0 (the output is the voices alone), rendered block by block."""
    from vibsynth.engine.engine import Engine

    return Engine(small_bank, channels=2, glide_s=0.0, initial_intensity=0.0)


@pytest.fixture
def controller(engine):
    from vibsynth.control.controller import Controller

    return Controller(engine)


@pytest.fixture(scope="session")
def renders(basis):
    """4 textures of the engine at its own rate (no resampling), half a second each."""
    from vibsynth.research.lab.stimuli import load_renders

    return load_renders(4, fs=RATE, seconds=0.5, seed=1, basis=basis)
