"""Fixtures of the C# client's tests."""

from pathlib import Path

import pytest

from tests.clients.mono import build_client_check


@pytest.fixture(scope="session")
def client_check(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``ClientCheck.exe``, compiled once per session."""
    return build_client_check(tmp_path_factory.mktemp("csharp"))
