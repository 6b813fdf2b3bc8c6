"""Run a snippet in a fresh interpreter with a deadline: for calls that, were they broken, would
hang or spin without the GIL (a pytest process could not be stopped then) or crash the process.

The child imports the same ``vibsynth`` as the test (so under ``scripts/sanitize.sh`` it gets the
sanitized extensions) and inherits the environment (``LD_PRELOAD``, ``ASAN_OPTIONS``, ...).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import vibsynth

#: The folder that holds the ``vibsynth`` package the tests import.
PACKAGE_ROOT = Path(vibsynth.__file__).resolve().parents[1]


def run_python(code: str, timeout: float = 60.0) -> str:
    """Run ``code`` in ``python -c`` and return what it printed.

    Raises
    ------
    AssertionError
        The child exited non-zero (an uncaught exception or a sanitizer report: its stderr is in
        the message) or did not end within ``timeout`` seconds.
    """
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(PACKAGE_ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    try:
        proc = subprocess.run(
            [sys.executable, "-c", textwrap.dedent(code)],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"did not end within {timeout} s (a hang or a spin)") from exc
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout
