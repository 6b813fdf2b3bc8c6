"""Ending a ``vibsynth serve`` process a test started."""

from __future__ import annotations

import subprocess


def stop_serve(proc: subprocess.Popen) -> None:
    """Stop a ``vibsynth serve`` started by a test: SIGTERM, then SIGKILL if it hangs."""
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
