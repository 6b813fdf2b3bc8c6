"""`vibsynth serve` on a terminal: a status line every second; not on a pipe."""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ARGS = [
    sys.executable,
    "-m",
    "vibsynth",
    "serve",
    "--output",
    "null",
    "--no-osc",
    "--no-midi",
    "--intensity",
    "0.3",
    "--balance",
    "0.5",
    "--seconds",
    "3.5",
]


def _run_on_a_pty(tmp_path: Path) -> str:
    env = {**os.environ, "VIBSYNTH_CONFIG": str(tmp_path / "none.yaml"), "XDG_CACHE_HOME": str(tmp_path)}
    (tmp_path / "none.yaml").write_text("version: 1\n")
    controller_fd, terminal_fd = pty.openpty()
    proc = subprocess.Popen(ARGS, cwd=ROOT, stdin=terminal_fd, stdout=terminal_fd, stderr=terminal_fd, env=env)
    os.close(terminal_fd)
    chunks = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            data = os.read(controller_fd, 4096)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=30)
    os.close(controller_fd)
    assert proc.returncode == 0
    return b"".join(chunks).decode("utf-8", "replace")


def test_status_line_every_second_on_a_terminal(tmp_path):
    text = _run_on_a_pty(tmp_path)
    updates = [part for part in text.split("\r") if part.startswith("ch1 I=")]
    assert len(updates) >= 2, text  # 3.5 s of serving: a line at 1 s, 2 s, 3 s
    last = updates[-1]
    # the null output is paced by the system clock: a loaded machine wakes it late now and then,
    # so the count is whatever it is; the line must carry it
    assert "I=0.30 B=+0.50" in last and re.search(r"\| underflows \d+ \|", last) and "load" in last, last


def test_no_status_line_on_a_pipe(tmp_path):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    result = subprocess.run(ARGS[:-1] + ["1.5"], cwd=ROOT, capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0
    assert "ch1 I=" not in result.stdout and "make it vibrate" in result.stdout
