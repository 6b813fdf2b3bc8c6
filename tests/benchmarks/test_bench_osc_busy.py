"""The busy-machine OSC benchmark (benchmarks/bench_osc_busy.py): a 2 s run with one spinning process."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_short_run_counts_what_was_sent_and_what_serve_counted(tmp_path):
    out = tmp_path / "osc_busy.json"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "bench_osc_busy.py"), "--seconds", "2", "--hogs", "1"]
    run = subprocess.run(
        [*cmd, "--rate", "2000", "--json", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr[-3000:]
    (row,) = json.loads(out.read_text())["runs"]
    assert row["hogs"] == 1 and row["plays"] >= 7
    assert row["sent"] >= 3000  # 2 s of 2,000 messages/s, and the plays
    assert row["lost"] == row["sent"] - row["counted"]
    assert 0 < row["fast_path"] <= row["counted"]
    assert row["queue_full"] == 0  # Python is never 32,768 messages behind at this rate
    assert "lost %" in run.stdout and f"{row['sent']:>9}" in run.stdout


def test_bad_arguments_are_one_line():
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_osc_busy.py"), "--hogs", "-1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and "Traceback" not in run.stderr and "--hogs 0..256" in run.stderr
