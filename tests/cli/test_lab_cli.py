"""``vibsynth lab``: sessions, plan, analyze and equalise on sessions answered by a known rule."""

from __future__ import annotations

import csv
import io
import json
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from vibsynth.cli import main
from vibsynth.research.lab.build import SessionRequest, new_session
from vibsynth.research.lab.protocol import VERSIONS, LabParameters
from vibsynth.research.lab.records import Answer
from vibsynth.research.lab.stimuli import load_renders

T0 = datetime(2026, 3, 1, 10, 0, tzinfo=timezone.utc)


@pytest.fixture(scope="module")
def root(tmp_path_factory, basis):
    """A sessions folder with one finished session of each protocol (6 renders) and one half-done."""
    folder = tmp_path_factory.mktemp("lab-sessions")
    stimuli = load_renders(6, fs=4000, seconds=1.0, seed=2, basis=basis)
    rng = np.random.default_rng(5)
    params = LabParameters(familiarisation_pairs=0)
    rules = {
        "dissimilarity": lambda t, p: Answer(value=abs(p[t.stimuli[0]]["t1"] - p[t.stimuli[1]]["t1"]) / 80),
        "intensity": lambda t, p: Answer(value=float(np.clip(np.exp(rng.normal(0, 0.1)), 0.2, 5))),
        "resynthesis": lambda t, p: Answer(
            ratings={v: 1.0 if v == "O" else 0.6 if v.startswith("S1") else 0.2 for v in VERSIONS}
        ),
    }
    for protocol, rule in rules.items():
        with new_session(folder, SessionRequest(protocol, "p01", 4, params), stimuli, basis=basis) as s:
            while s.next_trial is not None:
                s.record(rule(s.next_trial, s.params()), shown_at=T0, answered_at=T0 + timedelta(seconds=1))
    with new_session(folder, SessionRequest("dissimilarity", "p02", 9, params), stimuli, basis=basis) as s:
        for _ in range(5):
            s.record(Answer(value=0.3), shown_at=T0, answered_at=T0)
    return folder


def run(capsys, *argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert code == 0, out.err
    return out.out


def test_sessions_lists_progress(root, capsys):
    rows = json.loads(run(capsys, "lab", "sessions", "--folder", root, "--format", "json"))
    assert sorted((r["protocol"], r["participant"], r["done"], r["total"], r["complete"]) for r in rows) == [
        ("dissimilarity", "p01", 21, 21, True),
        ("dissimilarity", "p02", 5, 21, False),
        ("intensity", "p01", 6, 6, True),
        ("resynthesis", "p01", 6, 6, True),
    ]
    table = run(capsys, "lab", "sessions", "--folder", root)
    assert "p02-dissimilarity-" in table and "5/21" in table
    assert "no sessions in" in run(capsys, "lab", "sessions", "--folder", root / "empty")


def test_sessions_folder_comes_from_the_config(root, capsys, tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text(f"lab:\n  folder: {root}\n")
    assert "p02-dissimilarity-" in run(capsys, "lab", "sessions", "--config", config)


def test_plan_is_seeded(capsys):
    a = run(capsys, "lab", "plan", "dissimilarity", "--stimuli", "renders:6", "--seed", "3", "--format", "csv")
    b = run(capsys, "lab", "plan", "dissimilarity", "--stimuli", "renders:6", "--seed", "3", "--format", "csv")
    c = run(capsys, "lab", "plan", "dissimilarity", "--stimuli", "renders:6", "--seed", "4", "--format", "csv")
    assert a == b and a != c
    rows = list(csv.DictReader(io.StringIO(a)))
    assert [r["phase"] for r in rows] == ["familiarisation"] * 30 + ["test"] * 21
    assert len({tuple(sorted(r["stimuli"].split(" / "))) for r in rows[30:]}) == 21
    huge = run(capsys, "lab", "plan", "resynthesis", "--stimuli", "presets:cork,wood", "--seed", str(2**64 - 1))
    assert "cork" in huge and "S2:8" in huge


def test_analyze_dissimilarity_recovers_v1(root, capsys, tmp_path):
    name = next(p.name for p in root.iterdir() if p.name.startswith("p01-dissimilarity"))
    out = run(capsys, "lab", "analyze", name, "--folder", root, "--splits", "10", "--plot", tmp_path / "map.png")
    assert "21 ratings -> 21 pairs" in out and "8-fold CV" in out and "MDS map: t1 vs dimension 1 r = +1.00" in out
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"
    data = json.loads(run(capsys, "lab", "analyze", root / name, "--splits", "10", "--format", "json"))
    assert int(np.argmax(data["fit"]["weights"])) == 0 and data["fit"]["r2_mean"] > 0.9
    weights = list(
        csv.DictReader(io.StringIO(run(capsys, "lab", "analyze", root / name, "--splits", "5", "--format", "csv")))
    )
    assert weights[0]["component"] == "T1" and float(weights[0]["weight"]) > 0


def test_analyze_across_sessions_and_unfinished(root, capsys):
    both = sorted(p for p in root.iterdir() if "-dissimilarity-" in p.name)
    out = run(capsys, "lab", "analyze", *both, "--splits", "5")
    assert "2 session(s) (p01, p02), 26/42 trials answered" in out
    assert "agreement between participants" in out


def test_analyze_intensity_and_resynthesis(root, capsys, tmp_path):
    intensity = next(p for p in root.iterdir() if "-intensity-" in p.name)
    out = run(capsys, "lab", "analyze", intensity)
    assert "intensity model: judged dB" in out and "[paper: 0.90]" in out
    rows = list(csv.DictReader(io.StringIO(run(capsys, "lab", "analyze", intensity, "--format", "csv"))))
    assert len(rows) == 6 and all(0.2 <= float(r["gain"]) <= 5 for r in rows)
    resynthesis = next(p for p in root.iterdir() if "-resynthesis-" in p.name)
    rows = json.loads(run(capsys, "lab", "analyze", resynthesis, "--format", "json"))["summary"]
    assert {r["version"]: r["mean"] for r in rows} == pytest.approx(
        {"O": 1, "S1": 0.6, "S1:8": 0.6, "S2:8": 0.2, "M": 0.2}
    )
    out = run(capsys, "lab", "equalise", intensity, "-o", tmp_path / "eq")
    assert "6 stimuli equalised by 1 participant(s)" in out
    assert json.loads((tmp_path / "eq" / "set.json").read_text())["equalised"] is True


def test_lab_alone_serves_and_opens_the_lab_tab(monkeypatch):
    from vibsynth.cli import serve

    seen = {}
    monkeypatch.setattr(serve, "run", lambda args: seen.update(vars(args)) or 0)
    assert main(["lab", "--output", "null", "--seconds", "1", "--channels", "2"]) == 0
    assert seen["open_browser"] is True and seen["open_fragment"] == "#lab"
    assert seen["output"] == "null" and seen["channels"] == 2
