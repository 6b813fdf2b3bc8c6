"""Seeded trial orders of the three protocols: same seed, same order; another seed, another order.

Each protocol's plan is made from the stimulus ids and one ``numpy.random.default_rng(seed)``
in a fixed sequence of draws, so a plan can be rebuilt and checked from the seed alone.

* intensity: every stimulus ``repetitions`` times, in random order, each starting from a
  random gain (log-uniform over the middle half, in log units, of the gain range: neither
  always 1, which would anchor the answer, nor near an end of the slider);
* dissimilarity: every unordered pair with each stimulus against itself, ``n (n + 1) / 2``
  trials, in random order, which stimulus of a pair comes first drawn at random; before them
  a familiarisation block of random pairs (drawn without replacement while there are enough
  pairs), which is not saved as data;
* resynthesis: every original once, in random order, its 5 versions on slots 1-5 in a
  random order of their own.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibsynth.errors import ParameterError
from vibsynth.research.lab.protocol import VERSIONS, Protocol, check_protocol, check_seed

__all__ = ["Trial", "Plan", "all_pairs", "intensity_plan", "dissimilarity_plan", "resynthesis_plan", "make_plan"]


@dataclass(frozen=True)
class Trial:
    """One trial of a plan.

    Attributes
    ----------
    index : int
        1-based within its phase.
    phase : {"familiarisation", "test"}
    stimuli : tuple of str
        Ids in presentation order: intensity ``(stimulus,)``, dissimilarity ``(first, second)``,
        resynthesis ``(original,)``.
    slots : tuple of str
        Resynthesis: the version (``O``, ``S1``, ``S1:8``, ``S2:8``, ``M``) on slots 1..5; else empty.
    start_gain : float or None
        Intensity: the gain the slider starts from.
    """

    index: int
    phase: str
    stimuli: tuple[str, ...]
    slots: tuple[str, ...] = ()
    start_gain: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain data (session.json)."""
        out: dict[str, Any] = {"index": self.index, "stimuli": list(self.stimuli)}
        if self.slots:
            out["slots"] = list(self.slots)
        if self.start_gain is not None:
            out["start_gain"] = self.start_gain
        return out

    @classmethod
    def from_dict(cls, data: Any, phase: str) -> Trial:
        """Read back :meth:`to_dict` (a ``ValueError`` for anything else)."""
        if not isinstance(data, dict):
            raise ValueError("a trial must be a mapping")
        stimuli = data.get("stimuli")
        slots = data.get("slots", [])
        gain = data.get("start_gain")
        index = data.get("index")
        if not isinstance(index, int) or not isinstance(stimuli, list) or not all(isinstance(s, str) for s in stimuli):
            raise ValueError("a trial needs an integer index and a list of stimulus ids")
        if not isinstance(slots, list) or not all(isinstance(s, str) for s in slots):
            raise ValueError("slots must be a list of versions")
        if gain is not None and (not isinstance(gain, (int, float)) or not math.isfinite(gain) or gain <= 0):
            raise ValueError("start_gain must be a positive number")
        return cls(index, phase, tuple(stimuli), tuple(slots), None if gain is None else float(gain))


@dataclass(frozen=True)
class Plan:
    """The trials of a session.

    Attributes
    ----------
    protocol : str
    seed : int
    familiarisation : tuple of Trial
        Played first, not saved.
    test : tuple of Trial
        The data trials.
    """

    protocol: Protocol
    seed: int
    familiarisation: tuple[Trial, ...]
    test: tuple[Trial, ...]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (session.json)."""
        return {
            "familiarisation": [t.to_dict() for t in self.familiarisation],
            "test": [t.to_dict() for t in self.test],
        }


def _check_ids(ids: Sequence[str], minimum: int) -> list[str]:
    out = list(ids)
    if len(out) < minimum:
        raise ParameterError(f"need at least {minimum} stimuli, got {len(out)}")
    if len(set(out)) != len(out):
        raise ParameterError("stimulus ids must be unique")
    return out


def all_pairs(n: int) -> list[tuple[int, int]]:
    """Every unordered pair of ``n`` items with each item against itself: ``n (n + 1) / 2`` pairs ``i <= j``."""
    return [(i, j) for i in range(n) for j in range(i, n)]


def intensity_plan(
    ids: Sequence[str], *, seed: int, gain_min: float = 0.2, gain_max: float = 5.0, repetitions: int = 1
) -> Plan:
    """Every stimulus ``repetitions`` times in random order, each with a random starting gain.

    Parameters
    ----------
    ids : sequence of str
    seed : int
    gain_min, gain_max : float
        The slider's range.
    repetitions : int
        1..10.
    """
    seed = check_seed(seed)
    names = _check_ids(ids, 1)
    if not 1 <= repetitions <= 10:
        raise ParameterError(f"repetitions must be 1..10, got {repetitions}")
    rng = np.random.default_rng(seed)
    order = rng.permutation(np.tile(np.arange(len(names)), repetitions))
    lo, hi = math.log(gain_min), math.log(gain_max)
    mid, quarter = (lo + hi) / 2, (hi - lo) / 4
    starts = np.exp(rng.uniform(mid - quarter, mid + quarter, order.size))
    test = tuple(
        Trial(k + 1, "test", (names[i],), start_gain=float(f"{g:.6g}")) for k, (i, g) in enumerate(zip(order, starts))
    )
    return Plan("intensity", seed, (), test)


def dissimilarity_plan(ids: Sequence[str], *, seed: int, familiarisation: int = 30) -> Plan:
    """All pairs with self-pairs in random order, after ``familiarisation`` random pairs.

    Parameters
    ----------
    ids : sequence of str
        At least 2 stimuli.
    seed : int
    familiarisation : int
        Pairs in the familiarisation block (0 = none).
    """
    seed = check_seed(seed)
    names = _check_ids(ids, 2)
    if not 0 <= familiarisation <= 1000:
        raise ParameterError(f"familiarisation pairs must be 0..1000, got {familiarisation}")
    rng = np.random.default_rng(seed)
    pairs = all_pairs(len(names))

    def trials(indices: np.ndarray, phase: str) -> tuple[Trial, ...]:
        flips = rng.random(indices.size) < 0.5
        out = []
        for k, (p, flip) in enumerate(zip(indices, flips)):
            i, j = pairs[int(p)]
            first, second = (j, i) if flip else (i, j)
            out.append(Trial(k + 1, phase, (names[first], names[second])))
        return tuple(out)

    test = trials(rng.permutation(len(pairs)), "test")
    draws = [rng.permutation(len(pairs)) for _ in range(-(-familiarisation // len(pairs)))] if familiarisation else []
    fam = trials(np.concatenate(draws)[:familiarisation] if draws else np.zeros(0, dtype=int), "familiarisation")
    return Plan("dissimilarity", seed, fam, test)


def resynthesis_plan(ids: Sequence[str], *, seed: int) -> Plan:
    """Every original once in random order, its 5 versions on the 5 slots in random order.

    Parameters
    ----------
    ids : sequence of str
        The originals.
    seed : int
    """
    seed = check_seed(seed)
    names = _check_ids(ids, 1)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(names))
    test = tuple(
        Trial(k + 1, "test", (names[int(i)],), slots=tuple(VERSIONS[int(v)] for v in rng.permutation(len(VERSIONS))))
        for k, i in enumerate(order)
    )
    return Plan("resynthesis", seed, (), test)


def make_plan(
    protocol: str,
    ids: Sequence[str],
    *,
    seed: int,
    familiarisation: int = 30,
    gain_min: float = 0.2,
    gain_max: float = 5.0,
    repetitions: int = 1,
) -> Plan:
    """The plan of ``protocol`` (one of :data:`~vibsynth.research.lab.protocol.PROTOCOLS`)."""
    name = check_protocol(protocol)
    if name == "intensity":
        return intensity_plan(ids, seed=seed, gain_min=gain_min, gain_max=gain_max, repetitions=repetitions)
    if name == "dissimilarity":
        return dissimilarity_plan(ids, seed=seed, familiarisation=familiarisation)
    return resynthesis_plan(ids, seed=seed)
