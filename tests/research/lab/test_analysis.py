"""Analysis of sessions answered by scripted participants whose rule is known."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from vibsynth.errors import InputError
from vibsynth.research.lab.analysis import (
    analyze_dissimilarity,
    analyze_intensity,
    analyze_resynthesis,
    folds_for,
    write_equalised_set,
)
from vibsynth.research.lab.build import SessionRequest, new_session
from vibsynth.research.lab.protocol import VERSIONS, LabParameters
from vibsynth.research.lab.records import Answer
from vibsynth.research.lab.session import Session
from vibsynth.research.lab.stimuli import load_folder, load_renders

T0 = datetime(2026, 3, 1, 10, 0, tzinfo=timezone.utc)
FAST = LabParameters(familiarisation_pairs=0)


def answer_all(session: Session, rule) -> Session:
    while session.next_trial is not None:
        shown = T0 + timedelta(seconds=5 * session.done)
        session.record(
            rule(session.next_trial, session.params()), shown_at=shown, answered_at=shown + timedelta(seconds=2)
        )
    return session


def test_folds_shrink_for_small_sets():
    assert folds_for(171) == 10  # the paper's 18 stimuli
    assert folds_for(21) == 8  # 6 stimuli: 17 training pairs
    assert folds_for(10) == 4
    assert folds_for(6) == 2
    assert folds_for(5) == 0


@pytest.mark.shared
def test_intensity_model_recovers_a_band_level_equaliser(tmp_path, hatt_folder, basis, rng):
    """Participants who match the 80-200 Hz level (with some scatter) give the paper's model an R^2 near 1."""
    stimuli = load_folder(hatt_folder, seconds=1.0)
    sessions = []
    for k, who in enumerate(("p1", "p2", "p3")):
        s = new_session(tmp_path, SessionRequest("intensity", who, k, FAST), stimuli, basis=basis)
        ref = s.params()["reference"]["level_db"]

        def equaliser(trial, params):
            gain = 10 ** ((ref - params[trial.stimuli[0]]["level_db"] + rng.normal(0, 0.7)) / 20)
            return Answer(value=float(np.clip(gain, 0.2, 5.0)), plays=2, reference_plays=2)

        sessions.append(answer_all(s, equaliser))
    result = analyze_intensity(sessions)
    assert result.ids == sessions[0].meta["originals"] and len(result.ids) == 6
    assert result.r2 > 0.9 and result.slope == pytest.approx(1.0, abs=0.15)
    assert result.level_sd_after < 0.5 * result.level_sd_before
    assert result.participant_r > 0.9 and result.participants == ["p1", "p2", "p3"]
    assert result.reference_level_db == pytest.approx(np.median(result.level_db), abs=1e-3)
    np.testing.assert_allclose(result.mean_gain, np.exp(np.log(result.gains).mean(axis=0)))
    # stored as an equalised set, it loads as one, with the gains applied to the samples
    folder = write_equalised_set(result, sessions, tmp_path / "equalised")
    eq = load_folder(folder, seconds=1.0)
    assert eq.equalised and sorted(eq.ids) == sorted(result.ids)
    played = sessions[0].stimuli()
    for sid, gain in zip(result.ids, result.mean_gain):
        np.testing.assert_allclose(eq.by_id()[sid].samples, played[sid].samples * gain, rtol=1e-5, atol=1e-9)
    with pytest.raises(InputError, match="already exists"):
        write_equalised_set(result, sessions, folder)
    for s in sessions:
        s.close()


def test_dissimilarity_fit_on_6_stimuli_gives_v1_the_largest_weight(tmp_path, basis, rng):
    """21 pairs (6 stimuli) must fit: the rule rates |t1 difference| with noise."""
    stimuli = load_renders(6, fs=4000, seconds=1.0, seed=2, basis=basis)
    sessions = []
    for k in range(2):

        def rater(trial, params):
            a, b = trial.stimuli
            value = abs(params[a]["t1"] - params[b]["t1"]) / 80 + rng.normal(0, 0.03)
            return Answer(value=float(np.clip(value, 0, 1)))

        s = new_session(tmp_path, SessionRequest("dissimilarity", f"p{k}", 10 + k, FAST), stimuli, basis=basis)
        sessions.append(answer_all(s, rater))
    one = analyze_dissimilarity(sessions[:1], basis=basis, n_splits=20, seed=1)
    assert one.fit is not None and one.fit.cv == 8 and one.fit.n_pairs == 21
    assert one.largest_weight == 0 and one.fit.r2_mean > 0.7
    assert one.mds is not None and one.mds.component_r[0, 0] > 0.95  # the map's first axis is t1
    both = analyze_dissimilarity(sessions, basis=basis, n_splits=20, seed=1)
    assert both.table.counts.tolist() == [2] * 21 and both.largest_weight == 0
    assert both.participant_r > 0.8 and both.self_mean < 0.1
    assert both.to_dict()["fit"]["weights"][0] > 0


def test_dissimilarity_of_an_unfinished_session_reports_what_it_can(tmp_path, basis):
    stimuli = load_renders(4, fs=4000, seconds=1.0, seed=2, basis=basis)
    with new_session(tmp_path, SessionRequest("dissimilarity", "p", 1, FAST), stimuli, basis=basis) as s:
        for _ in range(4):
            s.record(Answer(value=0.5), shown_at=T0, answered_at=T0)
        result = analyze_dissimilarity([s], basis=basis, n_splits=5)
    assert result.fit is None and result.mds is None
    assert "4 rated pairs are too few" in result.problem and "no map" in result.problem


def test_resynthesis_summary_is_the_mean_and_sd_per_version(tmp_path, basis):
    stimuli = load_renders(3, fs=4000, seconds=1.0, seed=2, basis=basis)
    table = {
        "O": [1.0, 1.0, 0.9],
        "S1": [0.8, 0.7, 1.0],
        "S1:8": [0.9, 0.8, 0.85],
        "S2:8": [0.3, 0.2, 0.4],
        "M": [0.1, 0.3, 0.2],
    }
    with new_session(tmp_path, SessionRequest("resynthesis", "p", 1, FAST), stimuli, basis=basis) as s:
        answer_all(s, lambda trial, params: Answer(ratings={v: table[v][trial.index - 1] for v in VERSIONS}))
        result = analyze_resynthesis([s])
    rows = {r["version"]: r for r in result.summary()}
    for v in VERSIONS:
        assert rows[v]["n"] == 3
        assert rows[v]["mean"] == pytest.approx(np.mean(table[v]))
        assert rows[v]["sd"] == pytest.approx(np.std(table[v], ddof=1))
    assert set(result.per_original) == set(stimuli.ids)


def test_sessions_of_different_sets_or_protocols_are_not_mixed(tmp_path, basis):
    a = load_renders(3, fs=4000, seconds=1.0, seed=2, basis=basis)
    b = load_renders(4, fs=4000, seconds=1.0, seed=2, basis=basis)
    s1 = new_session(tmp_path, SessionRequest("resynthesis", "p", 1, FAST), a, basis=basis)
    s2 = new_session(tmp_path, SessionRequest("resynthesis", "q", 1, FAST), b, basis=basis)
    s3 = new_session(tmp_path, SessionRequest("intensity", "q", 1, FAST), a, basis=basis)
    with pytest.raises(InputError, match="used different stimulus sets"):
        analyze_resynthesis([s1, s2])
    with pytest.raises(InputError, match="analyse one protocol at a time"):
        analyze_resynthesis([s1, s3])
    with pytest.raises(InputError, match="no answered trials"):
        analyze_resynthesis([s1])
    with pytest.raises(InputError, match="not an intensity one"):
        analyze_intensity([s1])
    for s in (s1, s2, s3):
        s.close()
