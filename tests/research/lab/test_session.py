"""Session folders: never overwritten, one fsynced row per trial, resumed after a kill -9."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from vibsynth.errors import InputError, ParameterError
from vibsynth.research.lab.build import SessionRequest, new_session
from vibsynth.research.lab.protocol import MAX_SEED, VERSIONS, LabParameters
from vibsynth.research.lab.records import Answer, columns
from vibsynth.research.lab.session import Session, list_sessions
from vibsynth.research.lab.stimuli import load_renders

T0 = datetime(2026, 3, 1, 10, 0, tzinfo=timezone.utc)
FAST = LabParameters(familiarisation_pairs=4)


@pytest.fixture(scope="module")
def renders(basis):
    """6 textures of the engine on a balance grid, at 4 kHz (quick to analyse)."""
    return load_renders(6, fs=4000, seconds=1.0, seed=1, basis=basis)


def answer_for(session: Session) -> Answer:
    """A participant answering from a known rule: dissimilarity = |t1 difference| / 60."""
    trial = session.next_trial
    params = session.params()
    if session.protocol == "dissimilarity":
        a, b = trial.stimuli
        return Answer(value=min(1.0, abs(params[a]["t1"] - params[b]["t1"]) / 60.0), plays=1)
    if session.protocol == "intensity":
        return Answer(value=1.25, plays=2, reference_plays=1)
    ratings = {v: (1.0 if v == "O" else 0.5) for v in VERSIONS}
    return Answer(ratings=ratings, slot_plays={v: 1 for v in VERSIONS}, reference_plays=1)


def run_trials(session: Session, count: int) -> None:
    for _ in range(count):
        shown = T0 + timedelta(seconds=10 * (session.done + 1))
        session.record(answer_for(session), shown_at=shown, answered_at=shown + timedelta(seconds=2.5))


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_a_session_folder_holds_plan_stimuli_and_csv(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("dissimilarity", "p01", 7, FAST), renders, basis=basis) as s:
        assert s.folder.parent == tmp_path and s.folder.name.startswith("p01-dissimilarity-")
        meta = json.loads((s.folder / "session.json").read_text())
        assert meta["protocol"] == "dissimilarity" and meta["seed"] == 7 and meta["participant"] == "p01"
        assert meta["parameters"]["gap_s"] == 0.5 and meta["parameters"]["stimulus_s"] == 1.0
        assert meta["set"] == {
            "name": "renders:6",
            "kind": "renders",
            "equalised": False,
            "normalise": "band",
            "level_db": pytest.approx(-50.0),
        }
        assert len(meta["plan"]["test"]) == 21 and len(meta["plan"]["familiarisation"]) == 4
        assert sorted(p.name for p in (s.folder / "stimuli").iterdir()) == [f"render-{k}.wav" for k in range(1, 7)]
        run_trials(s, 3)
    rows = read_csv(s.folder / "trials.csv")
    assert list(rows[0]) == list(columns("dissimilarity"))
    assert [r["trial"] for r in rows] == ["1", "2", "3"]
    plan = meta["plan"]["test"]
    for row, trial in zip(rows, plan):
        assert [row["stimulus_a"], row["stimulus_b"]] == trial["stimuli"]
        assert row["file_a"] == f"stimuli/{trial['stimuli'][0]}.wav"
        expected = abs(float(row["t1_a"]) - float(row["t1_b"])) / 60.0
        assert float(row["rating"]) == pytest.approx(expected, abs=1e-5)
        assert row["participant"] == "p01" and row["response_s"] == "2.500"
        assert row["shown_at"].endswith("Z") and row["answered_at"] > row["shown_at"]


def test_the_ratings_csv_is_what_dissim_fit_reads(tmp_path, renders, basis, capsys):
    from vibsynth.cli import main
    from vibsynth.research.dissim import read_ratings

    with new_session(tmp_path, SessionRequest("dissimilarity", "p02", 3, FAST), renders, basis=basis) as s:
        run_trials(s, s.total)
        assert s.complete and s.next_trial is None
    table = read_ratings(s.folder / "trials.csv")
    assert table.n_rows == 21 and len(table.files) == 6 and table.pairs.shape == (21, 2)
    assert sorted(f.name for f in table.files) == [f"render-{k}.wav" for k in range(1, 7)]
    capsys.readouterr()
    code = main(["dissim", "fit", str(s.folder / "trials.csv"), "--splits", "5", "--cv", "5", "--format", "json"])
    assert code == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["n_pairs"] == 21 and len(fit["weights"]) == 8
    assert int(np.argmax(fit["weights"])) == 0  # the rule rated |t1 difference|: V1 carries it


def test_an_existing_folder_is_never_overwritten(tmp_path, renders, basis):
    taken = tmp_path / "mine"
    taken.mkdir()
    (taken / "precious.txt").write_text("keep")
    request = SessionRequest("intensity", "p01", 1, FAST)
    with pytest.raises(InputError, match="already exists; a session folder is never overwritten"):
        new_session(tmp_path, request, renders, basis=basis, folder=taken)
    assert (taken / "precious.txt").read_text() == "keep" and sorted(os.listdir(taken)) == ["precious.txt"]
    # two sessions started in the same second get two folders
    first = new_session(tmp_path, request, renders, basis=basis)
    second = new_session(tmp_path, request, renders, basis=basis)
    first.close(), second.close()
    assert first.folder != second.folder
    assert (first.folder / "session.json").is_file() and (second.folder / "session.json").is_file()


def test_path_characters_in_the_participant_id_are_refused_before_anything_is_written(tmp_path, renders, basis):
    for bad in ("../escape", "a/b", "..", "x\\y"):
        with pytest.raises(ParameterError, match="participant id"):
            new_session(tmp_path, SessionRequest("intensity", bad, 1), renders, basis=basis)
    assert list(tmp_path.iterdir()) == []


def test_resume_continues_where_the_csv_stops(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("resynthesis", "p03", MAX_SEED, FAST), renders, basis=basis) as s:
        run_trials(s, 2)
        folder = s.folder
    with Session.open(folder, write=True) as s:
        assert s.done == 2 and s.next_trial == s.plan.test[2] and s.seed == MAX_SEED
        run_trials(s, s.total - 2)
    rows = read_csv(folder / "trials.csv")
    assert [int(r["trial"]) for r in rows] == list(range(1, 7))
    assert all(r["rating_O"] == "1" and r["rating_M"] == "0.5" for r in rows)
    with Session.open(folder, write=True) as s, pytest.raises(InputError, match="the session is complete"):
        s.record(answer_for(s), shown_at=T0, answered_at=T0)


def test_a_truncated_last_row_is_dropped_on_resume(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("intensity", "p04", 5, FAST), renders, basis=basis) as s:
        run_trials(s, 3)
        folder = s.folder
    path = folder / "trials.csv"
    data = path.read_bytes()
    path.write_bytes(data[:-25])  # the third row cut in the middle, as a crash during its write would
    with Session.open(folder) as reader:  # read only: the cut row is not a trial, the file is untouched
        assert reader.done == 2
    assert path.read_bytes() == data[:-25]
    with Session.open(folder, write=True) as s:
        assert s.done == 2
        run_trials(s, 1)
    rows = read_csv(path)
    assert [r["trial"] for r in rows] == ["1", "2", "3"]
    assert all(len(r) == len(columns("intensity")) and None not in r for r in rows)


def test_a_csv_that_does_not_match_the_plan_is_refused_with_its_line(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("dissimilarity", "p05", 5, FAST), renders, basis=basis) as s:
        run_trials(s, 2)
        folder = s.folder
    path = folder / "trials.csv"
    lines = path.read_text().splitlines(keepends=True)
    lines[2] = lines[2].replace("render", "rendex", 1)
    path.write_text("".join(lines))
    with pytest.raises(InputError, match=r"trials.csv:3: does not match the session's plan"):
        Session.open(folder, write=True)
    path.write_text("trial,rating\n1,0.5\n")
    with pytest.raises(InputError, match=r"trials.csv:1: the header is not the dissimilarity protocol's"):
        Session.open(folder)
    (folder / "session.json").write_text("{broken")
    with pytest.raises(InputError, match=r"session.json:1: not valid JSON"):
        Session.open(folder)
    with pytest.raises(InputError, match="not a lab session folder"):
        Session.open(tmp_path)


def test_two_runners_cannot_append_to_one_session(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("intensity", "p06", 5, FAST), renders, basis=basis) as s:
        with pytest.raises(InputError, match="open in another runner"):
            Session.open(s.folder, write=True)
        with Session.open(s.folder) as reader:  # reading is fine
            assert reader.done == 0
    with Session.open(s.folder, write=True):
        pass


@pytest.mark.parametrize(
    "protocol, answer, message",
    [
        ("dissimilarity", Answer(value=1.5), r"rating = 1.5 is outside \[0, 1\]"),
        ("dissimilarity", Answer(value=float("nan")), "rating must be a number"),
        ("intensity", Answer(value=0.1), r"gain = 0.1 is outside \[0.2, 5\]"),
        ("intensity", Answer(value=1.0, plays=-1), "plays must be an integer"),
        ("resynthesis", Answer(ratings={v: 0.5 for v in VERSIONS}), "set the most similar version to 1"),
        ("resynthesis", Answer(ratings={"O": 1.0}), "rate all five versions"),
    ],
)
def test_bad_answers_write_nothing(tmp_path, renders, basis, protocol, answer, message):
    with new_session(tmp_path, SessionRequest(protocol, "p07", 5, FAST), renders, basis=basis) as s:
        with pytest.raises(ParameterError, match=message):
            s.record(answer, shown_at=T0, answered_at=T0)
        assert s.done == 0
    assert len((s.folder / "trials.csv").read_text().splitlines()) == 1


def test_list_sessions_shows_progress_and_skips_what_is_not_a_session(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("dissimilarity", "p08", 1, FAST), renders, basis=basis) as s:
        run_trials(s, 5)
    (tmp_path / "not-a-session").mkdir()
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "session.json").write_text("[]")
    sessions, problems = list_sessions(tmp_path)
    assert [(i.participant, i.done, i.total, i.complete) for i in sessions] == [("p08", 5, 21, False)]
    assert len(problems) == 1 and "broken" in problems[0] and "not a vibsynth lab session" in problems[0]
    assert list_sessions(tmp_path / "missing") == ([], [])


KILLER = textwrap.dedent(
    """
    import sys, time
    from datetime import datetime, timezone
    from vibsynth.research.lab.session import Session
    from vibsynth.research.lab.records import Answer
    with Session.open(sys.argv[1], write=True) as s:
        while s.next_trial is not None:
            now = datetime.now(timezone.utc)
            s.record(Answer(value=0.25, plays=1), shown_at=now, answered_at=now)
            print(s.done, flush=True)
            time.sleep(0.01)
    """
)


def test_kill_9_loses_at_most_the_trial_in_progress(tmp_path, renders, basis):
    with new_session(tmp_path, SessionRequest("dissimilarity", "p09", 2, FAST), renders, basis=basis) as s:
        folder = s.folder
    proc = subprocess.Popen([sys.executable, "-c", KILLER, str(folder)], stdout=subprocess.PIPE, text=True)
    seen = 0
    deadline = time.monotonic() + 60
    while seen < 8 and time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen = int(line)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert seen >= 8
    with Session.open(folder, write=True) as s:
        assert seen <= s.done < s.total  # every trial reported written is there (fsynced), at most one more
        for row, trial in zip(s.rows, s.plan.test):
            assert (row["stimulus_a"], row["stimulus_b"]) == trial.stimuli
        run_trials(s, s.total - s.done)
    assert len(read_csv(folder / "trials.csv")) == 21
