"""Shared fixtures: a seeded rng, the default basis, paths to ../shared data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: ../shared beside the repository; from a worktree in a folder of worktrees (/work/wt/<name>), ../../shared
SHARED = next(
    (p / "shared" for p in (ROOT.parent, ROOT.parent.parent) if (p / "shared").is_dir()), ROOT.parent / "shared"
)
HATT_PSD = SHARED / "datasets" / "hatt-psd" / "psd.csv.gz"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def basis():
    from vibsynth.formats.basis_file import default_basis

    return default_basis()


@pytest.fixture(scope="session")
def hatt_psd() -> Path:
    if not HATT_PSD.exists():
        pytest.skip(f"shared data not found at {HATT_PSD} (clone with ../shared beside the repo)")
    return HATT_PSD
