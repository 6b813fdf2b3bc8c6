"""``vibsynth --version``: the same answer as argparse's, before any sub-command is imported."""

from __future__ import annotations

import subprocess
import sys

from vibsynth._version import __version__

PROBE = """
import sys
from vibsynth.cli import main
code = main(["--version"])
heavy = sorted(m for m in ("numpy", "scipy", "aiohttp", "pydantic", "vibsynth.cli.serve") if m in sys.modules)
print("code", code, "heavy", ",".join(heavy) or "-")
"""


def test_version_answers_without_importing_the_sub_commands():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.splitlines() == [f"vibsynth {__version__}", "code 0 heavy -"]


def test_version_with_other_arguments_is_argparse_s():
    done = subprocess.run(
        [sys.executable, "-c", "from vibsynth.cli import main; main(['-v', '--version'])"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (done.returncode, done.stdout) == (0, f"vibsynth {__version__}\n")
