"""``vibsynth discover``: bad arguments are one line and exit 2 (the browse itself runs in a network
namespace: tests/control/oscquery/test_discovery_netns.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "argv",
    [["--seconds", "0"], ["--seconds", "nan"], ["--seconds", "61"], ["--format", "xml"], ["--json", "--format", "csv"]],
)
def test_bad_arguments_are_one_line_and_exit_2(argv):
    result = subprocess.run(
        [sys.executable, "-m", "vibsynth", "discover", *argv], capture_output=True, text=True, timeout=60
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and "error:" in lines[-1]
