"""The peers benchmark's statistics (benchmarks/peers_stats.py): median intervals, round-paired bootstrap."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from peers_stats import median_ci, paired_bootstrap, round_matrix  # noqa: E402

PERIOD_MS = 128 / 48.0  # one JACK cycle at 48 kHz / 128


def test_the_median_interval_covers_the_true_median_at_least_as_often_as_asked(rng):
    hits = 0
    for _ in range(400):
        x = rng.uniform(0.0, PERIOD_MS, 101)
        med, lo, hi = median_ci(x)
        assert lo <= med <= hi and lo in x and hi in x
        hits += lo <= PERIOD_MS / 2 <= hi
    assert hits / 400 >= 0.93


def test_800_trials_of_a_wait_over_one_cycle_give_a_median_known_to_a_tenth_of_a_ms(rng):
    widths = [np.subtract(*median_ci(rng.uniform(0.0, PERIOD_MS, n))[2:0:-1]) for n in (30, 800)]
    assert 0.3 < widths[0] / 2 < 0.6  # 30 trials: about +-0.2..0.5 ms
    assert widths[1] / 2 < 0.12  # 800 trials: about +-0.1 ms


def test_median_ci_of_nothing_is_nan_and_of_few_the_whole_range():
    assert all(math.isnan(v) for v in median_ci([]))
    assert median_ci([3.0, 1.0, 2.0]) == (2.0, 1.0, 3.0)


def test_round_matrix_puts_each_trial_in_its_round_and_leaves_missing_ones_nan():
    trials = {"a": [{"round": 0, "v": 1.0}, {"round": 2, "v": 3.0}], "b": [{"round": 1, "v": 5.0}]}
    names, m = round_matrix(trials, "v", 3)
    assert names == ["a", "b"]
    np.testing.assert_array_equal(m, [[1.0, np.nan], [np.nan, 5.0], [3.0, np.nan]])


def _diff(x: np.ndarray) -> np.ndarray:
    meds = np.nanmedian(x, axis=1)
    return meds[:, 1] - meds[:, 0]


def test_the_paired_bootstrap_finds_a_shift_and_its_size(rng):
    a = rng.uniform(0.0, PERIOD_MS, 800)
    m = np.column_stack([a, a + 0.2])  # the same wait, one engine 0.2 ms later
    value, lo, hi = paired_bootstrap(m, _diff, resamples=1000, seed=1)
    assert abs(value - 0.2) < 1e-9 and lo <= 0.2 <= hi and lo > 0.0


def test_pairing_by_round_narrows_the_interval_when_rounds_share_their_wait(rng):
    shared = rng.uniform(0.0, PERIOD_MS, 800)  # each round's wait, the same for both engines
    m = np.column_stack([shared + rng.normal(0, 0.05, 800), shared + rng.normal(0, 0.05, 800)])
    _, lo, hi = paired_bootstrap(m, _diff, resamples=1000, seed=2)
    unpaired = np.column_stack([m[:, 0], rng.permutation(m[:, 1])])  # the rounds' pairing broken
    _, ulo, uhi = paired_bootstrap(unpaired, _diff, resamples=1000, seed=2)
    assert lo <= 0.0 <= hi
    assert (hi - lo) < 0.5 * (uhi - ulo)


def test_the_bootstrap_is_reproducible_for_a_seed(rng):
    m = rng.uniform(0.0, PERIOD_MS, (200, 2))
    assert paired_bootstrap(m, _diff, resamples=500, seed=3) == paired_bootstrap(m, _diff, resamples=500, seed=3)
