"""The soak benchmark (benchmarks/bench_soak.py): its windows, its growth fit, and a 9 s run on the null output."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_soak import LISTENERS, PAGES, VANISH_KINDS, growth, schedule  # noqa: E402


def test_the_windows_tile_the_run_quiet_first_every_interval_and_last():
    windows = schedule(1800.0, 30.0, 300.0)
    assert [w[0] for w in windows[:4]] == ["quiet", "load", "quiet", "load"]
    assert windows[0][1:] == (0.0, 30.0) and windows[-1] == ("quiet", 1770.0, 1800.0)
    assert all(a[2] == b[1] for a, b in zip(windows, windows[1:]))  # no gap, no overlap
    quiet_starts = [w[1] for w in windows if w[0] == "quiet"]
    assert quiet_starts == [0.0, 300.0, 600.0, 900.0, 1200.0, 1500.0, 1770.0]
    assert sum(w[2] - w[1] for w in windows if w[0] == "quiet") == 210.0


def test_a_short_run_is_quiet_load_quiet():
    assert schedule(9.0, 1.5, 300.0) == [("quiet", 0.0, 1.5), ("load", 1.5, 7.5), ("quiet", 7.5, 9.0)]


def test_growth_is_the_slope_per_hour_after_the_warmup_without_the_samples_after_the_clients_left(rng):
    t = np.arange(0.0, 1800.0, 10.0)
    rss = 200.0 + 0.01 * t + rng.normal(0.0, 0.05, t.size)  # 36 MB per hour
    rss[t < 60.0] -= 50.0  # the start-up, before the first minute, is left out
    samples = [{"t": float(a), "window": "load", "rss_mb": float(b)} for a, b in zip(t, rss)]
    samples.append({"t": 1801.0, "window": "end", "rss_mb": 0.0})
    g = growth(samples, "rss_mb")
    assert g["per_hour"] == pytest.approx(36.0, abs=0.5)
    assert g["n"] == int(np.sum(t >= 60.0))
    assert g["min"] > 200.0 and g["range"] == pytest.approx(g["max"] - g["min"])
    flat = [{"t": float(a), "window": "load", "fds": 125} for a in t]
    assert growth(flat, "fds")["per_hour"] == 0.0 and growth(flat, "fds")["range"] == 0.0
    assert growth(flat[:3], "fds")["per_hour"] is None  # no sample after the first minute


def test_a_short_soak_on_the_null_output_writes_every_figure(tmp_path):
    out = tmp_path / "soak.json"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "bench_soak.py"), "--minutes", "0.15", "--output", "null"]
    cmd += ["--rate", "1000", "--quiet-seconds", "1.5", "--sample-seconds", "1", "--warmup-seconds", "2"]
    run = subprocess.run([*cmd, "--json", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(out.read_text())
    assert [w["window"] for w in result["windows"]] == ["quiet", "load", "quiet"]
    assert [w["flood_sent"] > 0 for w in result["windows"]] == [False, True, False]
    loaded = [s for s in result["samples"] if s["window"] == "load"]
    assert loaded and all(s["rss_mb"] > 10 and s["fds"] > LISTENERS and s["threads"] > 2 for s in loaded)
    assert all(s["oscquery_clients"] >= LISTENERS for s in loaded)  # the listeners (and vanishing sockets)
    end = result["samples"][-1]
    assert end["window"] == "end" and end["oscquery_clients"] == 0  # every client left
    messages = result["messages"]
    assert messages["flood"] > 1000 and messages["sent"] > messages["flood"]
    assert messages["lost"] == 0 and messages["received"] == messages["sent"]
    for key in ("rss_mb", "fds", "threads"):
        g = result["growth"][key]
        assert g["n"] >= 2 and g["min"] <= g["first"] <= g["max"] and g["per_hour"] is not None
    load = result["load"]
    assert load["clips_played"] >= 1 and load["reloads_written"] >= 1
    assert load["reloads_seen"] == load["reloads_written"]
    assert load["vanished"]["tcp-osc"] >= 1 and set(load["vanished"]) == set(VANISH_KINDS)
    assert load["listeners_silent"] < LISTENERS and load["page_messages"] >= PAGES  # each page got its hello
    assert load["disconnects"] == 0 and result["errors"]["benchmark"] == []
    assert result["underflows"]["quiet_seconds"] > 0 and result["underflows"]["load_seconds"] > 0
    assert "soak:" in run.stdout and "lost 0" in run.stdout
