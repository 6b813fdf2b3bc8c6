"""Shared fixtures: a small bank (fast to build) over the default basis."""

from __future__ import annotations

import pytest

from vibsynth.engine.bank import BankSpec, NoiseBank, build_bank
from vibsynth.formats.basis_file import default_basis

SMALL_SPEC = BankSpec(fs=16000.0, loop_seconds=2.0, balance_min=-3.5, balance_max=3.5, levels=29, seed=3)


@pytest.fixture(scope="session")
def basis():
    return default_basis()


@pytest.fixture(scope="session")
def small_bank(basis) -> NoiseBank:
    return build_bank(basis, SMALL_SPEC)
