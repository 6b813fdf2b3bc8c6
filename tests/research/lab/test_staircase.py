"""Staircases for iso-intensity matching: the rule's moves, the plan, convergence on a simulated observer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibsynth.errors import ParameterError
from vibsynth.research.lab.staircase import ESTIMATE_REVERSALS, check_method, staircase_plan, track

RANGE = {"low_db": -24.0, "high_db": 24.0}


def observer(pse_db: float, sigma_db: float, rng: np.random.Generator):
    """A participant who feels the test sine stronger with probability Phi((level - pse) / sigma)."""

    def answer(level_db: float) -> bool:
        p = 0.5 * (1 + math.erf((level_db - pse_db) / (sigma_db * math.sqrt(2))))
        return bool(rng.random() < p)

    return answer


def run(start_db, answer, n, rule="1u1d"):
    answers: list[bool] = []
    for _ in range(n):
        answers.append(answer(track(start_db, answers, rule=rule, **RANGE).next_db))
    return track(start_db, answers, rule=rule, **RANGE)


def test_one_up_one_down_moves_and_shrinks_its_steps():
    t = track(0.0, [True, True, False, True, False, True], **RANGE)
    # down 4, down 4, up 4 (1st reversal), down 2 (2nd: steps now 2), up 2 (3rd), down 1 (4th: steps now 1)
    assert t.levels_db == [0.0, -4.0, -8.0, -4.0, -6.0, -4.0, -5.0]
    assert t.reversals_db == [-8.0, -4.0, -6.0, -4.0]
    assert track(20.0, [False] * 5, **RANGE).levels_db[-1] == 24.0  # held in the range


def test_two_down_one_up_needs_two_strongers_in_a_row():
    t = track(0.0, [True, False, True, True], rule="2d1u", **RANGE)
    assert t.levels_db == [0.0, 0.0, 4.0, 4.0, 0.0]


@pytest.mark.parametrize("pse", [-15.0, 0.0, 12.0])
def test_a_deterministic_observer_is_found_within_a_step(pse):
    t = run(-10.0, lambda level: level > pse, 16)
    assert len(t.reversals_db) >= 2 + 4
    assert abs(t.estimate_db - pse) <= 1.0


def test_noisy_observers_converge_on_their_point_of_equality():
    rng = np.random.default_rng(3)
    errors = []
    for _ in range(200):
        pse = rng.uniform(-15, 15)
        start = pse + rng.choice([-1, 1]) * rng.uniform(6, 12)
        errors.append(run(start, observer(pse, 1.5, rng), 24).estimate_db - pse)
    errors = np.array(errors)
    assert abs(errors.mean()) < 0.3 and errors.std() < 1.5 and np.mean(np.abs(errors) <= 2.0) > 0.85


def test_two_down_one_up_sits_above_equality_as_levitt_says():
    rng = np.random.default_rng(4)
    errors = [run(8.0, observer(0.0, 2.0, rng), 40, rule="2d1u").estimate_db for _ in range(200)]
    # the 70.7 % point of a cumulative Gaussian: 0.545 sigma above equality
    assert np.mean(errors) == pytest.approx(0.545 * 2.0, abs=0.4)


def test_the_plan_interleaves_every_staircase_seeded():
    ids = [f"sine-{f}Hz" for f in (10, 20, 40, 80, 160, 320, 640, 1000)]
    a = staircase_plan(ids, seed=9, gain_min=1 / 16, gain_max=16, trials=12)
    assert a == staircase_plan(ids, seed=9, gain_min=1 / 16, gain_max=16, trials=12)
    assert a.test != staircase_plan(ids, seed=10, gain_min=1 / 16, gain_max=16, trials=12).test
    order = [t.stimuli[0] for t in a.test]
    assert len(order) == 96 and all(order.count(i) == 12 for i in ids)
    firsts = {}
    for t in a.test:
        firsts.setdefault(t.stimuli[0], t)
    assert all(t.start_gain is not None and abs(20 * math.log10(t.start_gain)) <= 12 for t in firsts.values())
    assert sum(t.start_gain is not None for t in a.test) == len(ids)
    with pytest.raises(ParameterError, match="trials per sine must be 6..60"):
        staircase_plan(ids, seed=1, gain_min=0.1, gain_max=10, trials=2)
    with pytest.raises(ParameterError, match="unknown method 'bisect'"):
        check_method("bisect")


def test_the_estimate_uses_the_last_reversals():
    t = track(0.0, [True, False] * 10, **RANGE)
    assert t.estimate_db == pytest.approx(np.mean(t.reversals_db[2:][-ESTIMATE_REVERSALS:]))
