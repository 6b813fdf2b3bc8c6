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


#: The unit phase's longest files (seconds on the 2-core VM, .ci/run of 2026-12-07), handed out first.
#: ``--dist loadfile`` gives each worker the next file in collection order, which is alphabetical:
#: test_docs.py (~190 s) came last and the other worker then sat idle for minutes.
LONGEST_FIRST = (
    "tests/test_docs.py",  # ~190
    "tests/e2e/test_lab_iso_e2e.py",  # ~90
    "tests/test_packaging.py",  # ~70
    "tests/clients/test_csharp_discover.py",  # ~40
    "tests/e2e/test_lab_e2e.py",  # ~35
    "tests/scripts/test_wheels.py",
    "tests/control/oscquery/test_discovery_netns.py",
    "tests/benchmarks/test_bench_soak.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The longest files first (a stable sort: within a file, and for the rest, the order stays)."""
    rank = {path: k for k, path in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::", 1)[0].replace("\\", "/"), len(rank)))
