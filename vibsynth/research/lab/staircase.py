"""Adaptive staircases for iso-intensity matching: "is the sine stronger or weaker than the reference?"

An alternative to adjusting a slider: each trial plays the reference sine and a test sine at a
level the staircase chooses; the participant answers *stronger* or *weaker*. One staircase
per frequency, all interleaved in a seeded random order (a fixed number of trials each), so
the plan is known in advance and a session resumes from its CSV like any other: the level of
every trial is a function of the plan's starting level and the answers so far (:func:`track`).

Rules (the level is the test sine's drive, dB re the reference's):

* ``1u1d`` (default): *stronger* -> down one step, *weaker* -> up. It converges to the level
  answered *stronger* half the time: the point of subjective equality, what matching asks.
* ``2d1u``: two *stronger* in a row -> down, one *weaker* -> up: converges to the level judged
  stronger 70.7 % of the time (Levitt 1971), i.e. above equality by about half a psychometric
  width; steadier, but a biased match (say so when you report it).

Steps are 4 dB, then 2 dB after the 2nd reversal and 1 dB after the 4th; the level stays in
the session's gain range. The estimate is the mean level at the last :data:`ESTIMATE_REVERSALS`
reversals after the first two (the mean of the second half of the levels when there are too
few reversals).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vibsynth.errors import ParameterError
from vibsynth.research.lab.orders import Plan, Trial
from vibsynth.research.lab.protocol import check_seed

__all__ = [
    "RULES",
    "METHODS",
    "STEPS_DB",
    "TRIALS_PER_SINE",
    "ESTIMATE_REVERSALS",
    "Track",
    "check_method",
    "track",
    "staircase_plan",
]

#: Downs (consecutive *stronger*) and ups (*weaker*) that move the level, per rule.
RULES: dict[str, tuple[int, int]] = {"1u1d": (1, 1), "2d1u": (2, 1)}
#: How a session on sines is run: the slider (``adjustment``) or a staircase with a rule.
METHODS = ("adjustment", "staircase", "staircase-2d1u")
#: Step (dB) from the start, after 2 reversals, after 4.
STEPS_DB = ((0, 4.0), (2, 2.0), (4, 1.0))
#: Trials of each staircase (each sine) by default, and the bounds a request may ask for.
TRIALS_PER_SINE = 16
TRIALS_RANGE = (6, 60)
#: Reversals (after the first two) averaged for the estimate.
ESTIMATE_REVERSALS = 6


def check_method(method: object) -> str:
    """A method name of :data:`METHODS`; a :class:`ParameterError` listing them otherwise."""
    if method not in METHODS:
        raise ParameterError(f"unknown method {str(method)[:40]!r}; choose one of {', '.join(METHODS)}")
    return str(method)


def rule_of(method: str) -> str:
    """The staircase rule of a method (``staircase`` is 1-up/1-down)."""
    return "2d1u" if method == "staircase-2d1u" else "1u1d"


@dataclass(frozen=True)
class Track:
    """One staircase after some answers.

    Attributes
    ----------
    levels_db : list of float
        The level of each trial answered, then the next trial's level (``len(answers) + 1``).
    reversals_db : list of float
        Levels where the direction turned.
    """

    levels_db: list[float]
    reversals_db: list[float]

    @property
    def next_db(self) -> float:
        """The level of the next trial."""
        return self.levels_db[-1]

    @property
    def estimate_db(self) -> float:
        """The matched level: the mean of the last reversals (nan before any answer)."""
        usable = self.reversals_db[2:][-ESTIMATE_REVERSALS:]
        if len(usable) >= 2:
            return float(np.mean(usable))
        answered = self.levels_db[:-1]
        if not answered:
            return math.nan
        return float(np.mean(answered[len(answered) // 2 :]))


def track(start_db: float, stronger: Sequence[bool], *, rule: str = "1u1d", low_db: float, high_db: float) -> Track:
    """Run a staircase from ``start_db`` through answers (True = the test sine felt stronger).

    Parameters
    ----------
    start_db : float
    stronger : sequence of bool
    rule : {"1u1d", "2d1u"}
    low_db, high_db : float
        The level's range (the session's gains in dB).

    Returns
    -------
    track : Track
    """
    if rule not in RULES:
        raise ParameterError(f"unknown staircase rule {rule!r}; choose one of {', '.join(RULES)}")
    downs_needed, _ = RULES[rule]
    level = min(max(float(start_db), low_db), high_db)
    levels: list[float] = [level]
    reversals: list[float] = []
    direction, run = 0, 0
    for answer in stronger:
        step = next(s for after, s in reversed(STEPS_DB) if len(reversals) >= after)
        move = 0
        if answer:
            run += 1
            if run >= downs_needed:
                move, run = -1, 0
        else:
            move, run = 1, 0
        if move:
            if direction and move != direction:
                reversals.append(level)
                step = next(s for after, s in reversed(STEPS_DB) if len(reversals) >= after)
            direction = move
            level = min(max(level + move * step, low_db), high_db)
        levels.append(level)
    return Track(levels, reversals)


def staircase_plan(
    ids: Sequence[str], *, seed: int, gain_min: float, gain_max: float, trials: int = TRIALS_PER_SINE
) -> Plan:
    """Every sine's staircase ``trials`` times, interleaved in a seeded random order.

    The first trial of each staircase carries its starting gain (log-uniform within the middle
    half of the range in dB, as the adjustment's starts); later trials carry none (their level
    comes from the answers, :func:`track`).

    Parameters
    ----------
    ids : sequence of str
    seed : int
    gain_min, gain_max : float
    trials : int
        Per sine, :data:`TRIALS_RANGE`.
    """
    seed = check_seed(seed)
    if not TRIALS_RANGE[0] <= trials <= TRIALS_RANGE[1]:
        raise ParameterError(f"staircase trials per sine must be {TRIALS_RANGE[0]}..{TRIALS_RANGE[1]}, got {trials}")
    names = list(ids)
    if not names or len(set(names)) != len(names):
        raise ParameterError("a staircase plan needs unique stimulus ids")
    rng = np.random.default_rng([seed, 4])
    lo, hi = math.log(gain_min), math.log(gain_max)
    mid, quarter = (lo + hi) / 2, (hi - lo) / 4
    starts = np.exp(rng.uniform(mid - quarter, mid + quarter, len(names)))
    order = rng.permutation(np.repeat(np.arange(len(names)), trials))
    seen: set[int] = set()
    test = []
    for k, i in enumerate(order):
        first = int(i) not in seen
        seen.add(int(i))
        test.append(Trial(k + 1, "test", (names[int(i)],), start_gain=float(f"{starts[i]:.6g}") if first else None))
    return Plan("intensity", seed, (), tuple(test))
