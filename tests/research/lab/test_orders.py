"""Trial orders: complete, random, and the same for the same seed."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from vibsynth.errors import ParameterError
from vibsynth.research.lab.orders import (
    all_pairs,
    dissimilarity_plan,
    intensity_plan,
    make_plan,
    resynthesis_plan,
)
from vibsynth.research.lab.protocol import MAX_SEED, VERSIONS

IDS = [f"s{k:02d}" for k in range(18)]


def test_all_pairs_with_self_pairs_is_the_papers_171_for_18():
    assert len(all_pairs(18)) == 171
    assert len(all_pairs(6)) == 21


def test_dissimilarity_plays_every_pair_once_with_self_pairs():
    plan = dissimilarity_plan(IDS, seed=3)
    unordered = Counter(tuple(sorted(t.stimuli)) for t in plan.test)
    assert len(plan.test) == 171
    assert set(unordered.values()) == {1}
    assert sum(a == b for a, b in unordered) == 18
    assert [t.index for t in plan.test] == list(range(1, 172))
    # which stimulus comes first is random, not always the lower id
    distinct = [t.stimuli for t in plan.test if t.stimuli[0] != t.stimuli[1]]
    first_lower = sum(a < b for a, b in distinct)
    assert 0.35 < first_lower / len(distinct) < 0.65


def test_same_seed_same_order_other_seed_other_order():
    a = dissimilarity_plan(IDS, seed=11)
    assert a == dissimilarity_plan(IDS, seed=11)
    b = dissimilarity_plan(IDS, seed=12)
    assert [t.stimuli for t in a.test] != [t.stimuli for t in b.test]
    assert sorted(tuple(sorted(t.stimuli)) for t in a.test) == sorted(tuple(sorted(t.stimuli)) for t in b.test)


def test_order_is_random_not_sorted(rng):
    # Spearman correlation of presentation position with the pair's index in sorted order is near 0
    pairs = [tuple(sorted(t.stimuli)) for t in dissimilarity_plan(IDS, seed=int(rng.integers(1 << 30))).test]
    rank = np.argsort(np.argsort(pairs, axis=0)[:, 0])
    r = np.corrcoef(rank, np.arange(rank.size))[0, 1]
    assert abs(r) < 0.3


def test_familiarisation_block_is_30_random_pairs_by_default_and_separate():
    plan = dissimilarity_plan(IDS, seed=5)
    assert len(plan.familiarisation) == 30
    assert {t.phase for t in plan.familiarisation} == {"familiarisation"}
    assert {t.phase for t in plan.test} == {"test"}
    assert len({tuple(sorted(t.stimuli)) for t in plan.familiarisation}) == 30  # without replacement
    assert [t.stimuli for t in plan.familiarisation] != [t.stimuli for t in plan.test[:30]]
    assert dissimilarity_plan(IDS, seed=5, familiarisation=0).familiarisation == ()
    # more familiarisation pairs than pairs: every pair, then again
    small = dissimilarity_plan(IDS[:3], seed=5, familiarisation=8)
    assert len(small.familiarisation) == 8
    assert len({tuple(sorted(t.stimuli)) for t in small.familiarisation[:6]}) == 6


def test_huge_seed_gives_a_reproducible_plan():
    assert dissimilarity_plan(IDS, seed=MAX_SEED) == dissimilarity_plan(IDS, seed=MAX_SEED)
    assert dissimilarity_plan(IDS, seed=MAX_SEED) != dissimilarity_plan(IDS, seed=MAX_SEED - 1)
    with pytest.raises(ParameterError, match="seed must be an integer"):
        dissimilarity_plan(IDS, seed=MAX_SEED + 1)


def test_intensity_plays_every_stimulus_with_a_start_gain_in_the_middle_of_the_range():
    plan = intensity_plan(IDS, seed=2, repetitions=3)
    assert Counter(t.stimuli[0] for t in plan.test) == {sid: 3 for sid in IDS}
    logs = np.log([t.start_gain for t in plan.test])
    lo, hi = math.log(0.2), math.log(5.0)
    assert np.all(logs >= lo + (hi - lo) / 4 - 1e-9) and np.all(logs <= hi - (hi - lo) / 4 + 1e-9)
    assert np.std(logs) > 0.2  # not all the same
    assert plan.familiarisation == ()
    assert [t.stimuli for t in plan.test] != [t.stimuli for t in intensity_plan(IDS, seed=3, repetitions=3).test]


def test_resynthesis_puts_the_five_versions_in_random_slots():
    plan = resynthesis_plan(IDS, seed=9)
    assert sorted(t.stimuli[0] for t in plan.test) == sorted(IDS)
    assert all(sorted(t.slots) == sorted(VERSIONS) for t in plan.test)
    hidden_reference_slots = Counter(t.slots.index("O") for t in plan.test)
    assert len(hidden_reference_slots) >= 4  # the hidden reference moves around
    assert plan == resynthesis_plan(IDS, seed=9)
    assert [t.slots for t in plan.test] != [t.slots for t in resynthesis_plan(IDS, seed=10).test]


def test_bad_inputs():
    with pytest.raises(ParameterError, match="at least 2 stimuli"):
        dissimilarity_plan(["a"], seed=1)
    with pytest.raises(ParameterError, match="unique"):
        resynthesis_plan(["a", "a"], seed=1)
    with pytest.raises(ParameterError, match="unknown protocol"):
        make_plan("abx", IDS, seed=1)
    with pytest.raises(ParameterError, match="repetitions"):
        intensity_plan(IDS, seed=1, repetitions=0)


def test_plan_round_trips_through_plain_data():
    from vibsynth.research.lab.orders import Trial

    plan = resynthesis_plan(IDS, seed=4)
    data = plan.to_dict()
    assert tuple(Trial.from_dict(t, "test") for t in data["test"]) == plan.test
