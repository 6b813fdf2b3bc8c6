"""The runner on a real engine rendered offline: exact schedules, silence between trials, the CSV."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from tests.app.lab.conftest import RATE
from vibsynth.app.lab.runner import LEAD_S, LabRunner
from vibsynth.errors import InputError, ParameterError
from vibsynth.research.lab.build import SessionRequest, new_session
from vibsynth.research.lab.protocol import LabParameters
from vibsynth.research.lab.session import Session

PARAMS = LabParameters(stimulus_s=0.5, gap_s=0.25, familiarisation_pairs=2)
FADE = int(round(0.005 * RATE))  # the engine's voice edge fade
LEAD = int(round(LEAD_S * RATE))
N = int(0.5 * RATE)
GAP = int(0.25 * RATE)


def session(tmp_path, renders, basis, protocol, seed=3, params=PARAMS):
    return new_session(tmp_path, SessionRequest(protocol, "p01", seed, params), renders, basis=basis)


def render(engine, frames):
    return engine.render(frames)[:, 0].astype(np.float64)


def sound(s, sid):
    return s.stimuli()[sid].samples.astype(np.float32).astype(np.float64)


def assert_plays(out, samples, at, gain=1.0):
    """``samples`` (times gain) sound from ``at`` on, exactly, inside the edge fades."""
    inside = slice(at + FADE, at + samples.size - FADE)
    np.testing.assert_allclose(out[inside], gain * samples[FADE : samples.size - FADE], atol=1e-6)


def test_a_pair_plays_stimulus_gap_stimulus_sample_exactly(tmp_path, renders, basis, engine, controller):
    s = session(tmp_path, renders, basis, "dissimilarity")
    runner = LabRunner(engine, controller)
    start = engine.frame_position
    state = runner.start(s)
    assert state["status"] == "running" and state["phase"] == "familiarisation" and state["progress"] == [0, 10]
    a, b = s.plan.familiarisation[0].stimuli
    out = render(engine, LEAD + 2 * N + GAP + 400)
    at = start + LEAD - start  # output index of the first sample
    assert np.all(out[:at] == 0)
    assert_plays(out, sound(s, a), at)
    assert np.all(out[at + N : at + N + GAP] == 0)  # 250 ms of silence, to the sample
    assert_plays(out, sound(s, b), at + N + GAP)
    assert np.all(out[at + 2 * N + GAP :] == 0)
    runner.stop()


def test_nothing_plays_after_an_answer_not_even_a_pairs_waiting_second_stimulus(
    tmp_path, renders, basis, engine, controller
):
    s = session(tmp_path, renders, basis, "dissimilarity")
    runner = LabRunner(engine, controller)
    runner.start(s)
    render(engine, LEAD + N // 2)  # half-way through the first stimulus
    runner.answer(value=0.5)  # familiarisation trial 1 answered early: its B must never sound
    # B was due N // 2 + GAP from now: the next trial's pair starts one frame after, silence until then
    b_due = N // 2 + GAP
    out = render(engine, b_due + 1 + 2 * N + GAP)
    assert np.max(np.abs(out[FADE + 64 : b_due + 1])) == 0.0
    first, second = s.plan.familiarisation[1].stimuli
    assert_plays(out, sound(s, first), b_due + 1)
    assert_plays(out, sound(s, second), b_due + 1 + N + GAP)
    runner.answer(value=0.5)  # answered after the pair: the next one starts LEAD later
    out = render(engine, LEAD + N // 2)
    assert np.max(np.abs(out[:LEAD])) == 0.0
    runner.pause()  # during the first stimulus: silence, the waiting second one cancelled
    out = render(engine, 2 * N + GAP)
    assert np.max(np.abs(out[FADE + 64 :])) == 0.0
    runner.stop()


def test_familiarisation_is_not_saved_and_progress_counts_data_trials(tmp_path, renders, basis, engine, controller):
    s = session(tmp_path, renders, basis, "dissimilarity")
    runner = LabRunner(engine, controller)
    runner.start(s)
    assert runner.answer(value=0.1)["phase"] == "familiarisation"
    state = runner.answer(value=0.2)
    assert state["phase"] == "test" and state["progress"] == [1, 10] and state["familiarisation"] == [2, 2]
    state = runner.answer(value=0.7)
    assert state["progress"] == [2, 10]
    with open(s.trials_path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["rating"] for r in rows] == ["0.7"]  # the two familiarisation answers are not there
    assert (rows[0]["stimulus_a"], rows[0]["stimulus_b"]) == s.plan.test[0].stimuli
    assert rows[0]["plays"] == "1"
    runner.stop()


def test_the_state_never_names_a_stimulus(tmp_path, renders, basis, engine, controller):
    published = []
    s = session(tmp_path, renders, basis, "resynthesis")
    runner = LabRunner(engine, controller, on_change=published.append)
    runner.start(s)
    runner.play(slot=2)
    runner.answer(ratings={1: 1.0, 2: 0.5, 3: 0.4, 4: 0.3, 5: 0.2})
    names = [*s.stimuli(), "render", "S1", "S2:8"]
    for state in published + [runner.state()]:
        text = json.dumps(state)
        assert not any(name in text for name in names), text
    runner.stop()


def test_resynthesis_plays_the_slots_version_and_saves_ratings_by_version(tmp_path, renders, basis, engine, controller):
    s = session(tmp_path, renders, basis, "resynthesis")
    runner = LabRunner(engine, controller)
    state = runner.start(s)
    assert state["slots"] == 5
    trial = s.plan.test[0]
    out = render(engine, LEAD + N + 100)
    assert_plays(out, sound(s, trial.stimuli[0]), LEAD)  # shown: the original (the reference) plays
    for slot, version in enumerate(trial.slots, start=1):
        runner.play(slot=slot)
        out = render(engine, LEAD + N + 100)
        sid = trial.stimuli[0] if version == "O" else f"{trial.stimuli[0]}.{version.replace(':', '-')}"
        assert_plays(out, sound(s, sid), LEAD)
    runner.play(slot=3)
    ratings = {k: round(0.2 * k, 2) for k in range(1, 6)}
    ratings[4] = 1.0
    runner.answer(ratings=ratings)
    with open(s.trials_path, newline="") as handle:
        row = next(csv.DictReader(handle))
    for slot, version in enumerate(trial.slots, start=1):
        assert row[f"slot_{slot}"] == version
        assert float(row[f"rating_{version}"]) == ratings[slot]
        assert row[f"plays_{version}"] == ("2" if slot == 3 else "1")
    assert row["reference_plays"] == "1"
    with pytest.raises(ParameterError, match="rate every slot"):
        runner.answer(ratings={1: 1.0})
    with pytest.raises(ParameterError, match="set the most similar version to 1"):
        runner.answer(ratings={k: 0.5 for k in range(1, 6)})
    runner.stop()


def test_intensity_plays_at_the_sliders_gain_and_the_reference_at_1(tmp_path, renders, basis, engine, controller):
    s = session(tmp_path, renders, basis, "intensity")
    runner = LabRunner(engine, controller)
    runner.start(s)
    trial = s.plan.test[0]
    out = render(engine, LEAD + N + 100)
    assert_plays(out, sound(s, trial.stimuli[0]), LEAD, gain=trial.start_gain)
    runner.play(gain=2.5)
    out = render(engine, LEAD + N + 100)
    assert_plays(out, sound(s, trial.stimuli[0]), LEAD, gain=2.5)
    runner.play_reference()
    out = render(engine, LEAD + N + 100)
    assert_plays(out, sound(s, "reference"), LEAD)
    runner.play(gain=1.0)
    render(engine, LEAD + 100)
    runner.set_gain(3.0)  # live: the stimulus goes on at the new gain after a 10 ms glide
    out = render(engine, N // 2)
    tail = slice(int(0.02 * RATE), N // 2 - 200)
    np.testing.assert_allclose(
        out[tail], 3.0 * sound(s, trial.stimuli[0])[100 + tail.start : 100 + tail.stop], atol=1e-5
    )
    with pytest.raises(ParameterError, match=r"gain = 7 is outside \[0.2, 5\]"):
        runner.answer(value=7.0)
    runner.answer(value=1.5)
    with open(s.trials_path, newline="") as handle:
        row = next(csv.DictReader(handle))
    assert row["gain"] == "1.5" and row["plays"] == "3" and row["reference_plays"] == "1"
    assert float(row["start_gain"]) == trial.start_gain
    runner.stop()


def test_the_texture_is_muted_during_a_run_and_restored_after(tmp_path, renders, basis, engine, controller):
    controller.set_mute(True, channels=[1])
    runner = LabRunner(engine, controller)
    runner.start(session(tmp_path, renders, basis, "intensity"))
    assert controller.get("mute", 0) is True and controller.get("mute", 1) is True
    runner.stop()
    assert controller.get("mute", 0) is False and controller.get("mute", 1) is True  # as before the run


def test_a_run_goes_to_done_and_resumes_from_the_csv(tmp_path, renders, basis, engine, controller):
    s = session(tmp_path, renders, basis, "intensity", params=LabParameters(stimulus_s=0.5))
    runner = LabRunner(engine, controller)
    runner.start(s)
    runner.answer(value=1.0)
    runner.answer(value=2.0)
    runner.stop()  # the experimenter stops; the CSV has 2 trials
    again = Session.open(s.folder, write=True)
    state = runner.start(again)
    assert state["progress"] == [3, 4] and state["phase"] == "test"
    runner.answer(value=0.5)
    state = runner.answer(value=0.25)
    assert state["status"] == "done" and state["progress"] == [4, 4] and state["folder"] == str(s.folder)
    assert controller.get("mute", 0) is False
    with pytest.raises(InputError, match="no trial is shown"):
        runner.play()
    with pytest.raises(InputError, match="the session is complete"):
        runner.start(Session.open(s.folder, write=True))
    assert len(Session.open(s.folder).rows) == 4


def test_one_run_at_a_time_and_panic_pauses(tmp_path, renders, basis, engine, controller):
    runner = LabRunner(engine, controller)
    runner.start(session(tmp_path, renders, basis, "intensity"))
    with pytest.raises(InputError, match="already running"):
        runner.start(session(tmp_path, renders, basis, "intensity", seed=4))
    controller.panic()
    state = runner.state()
    assert state["status"] == "paused" and "panic" in state["error"]
    with pytest.raises(InputError, match="paused"):
        runner.answer(value=1.0)
    assert runner.resume()["status"] == "running"
    runner.close()
