"""One CSV row per trial: the columns of each protocol, the row of an answer, and its check on resume.

The dissimilarity CSV is the one ``vibsynth dissim fit`` reads: its header names ``file_a``,
``file_b`` and ``rating`` (the stimuli's WAVs, relative to the CSV's folder); the other
columns (ids, t1 of each stimulus, replays, timestamps) are ignored by it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from vibsynth.errors import ParameterError
from vibsynth.research.lab.orders import Trial
from vibsynth.research.lab.protocol import VERSIONS, Protocol

__all__ = [
    "MAX_PLAYS",
    "JUDGEMENTS",
    "Answer",
    "columns",
    "make_row",
    "check_row",
    "timestamp",
    "parse_timestamp",
    "stimulus_file",
]

#: Plays of one sound counted per trial, at most (a stuck key cannot grow a number without bound).
MAX_PLAYS = 10_000

_COMMON_TAIL = ("shown_at", "answered_at", "response_s", "participant")
_COLUMNS: dict[str, tuple[str, ...]] = {
    "intensity": (
        "trial",
        "stimulus",
        "file",
        "gain",
        "log10_gain",
        "start_gain",
        "plays",
        "reference_plays",
        "level_db",
        "equalised_level_db",
        "broadband_db",
        "t1",
        "reference",
    )
    + _COMMON_TAIL,
    "dissimilarity": (
        "trial",
        "file_a",
        "file_b",
        "rating",
        "stimulus_a",
        "stimulus_b",
        "plays",
        "t1_a",
        "t1_b",
        "level_db_a",
        "level_db_b",
    )
    + _COMMON_TAIL,
    "resynthesis": (
        ("trial", "original")
        + tuple(f"slot_{k}" for k in range(1, 6))
        + tuple(f"rating_{v}" for v in VERSIONS)
        + tuple(f"plays_{v}" for v in VERSIONS)
        + ("reference_plays", "t1", "level_db")
        + _COMMON_TAIL
    ),
}


#: A staircase session's extra column: the participant's judgement of the test sine vs the reference.
JUDGEMENTS = ("stronger", "weaker")


def columns(protocol: Protocol, method: str = "adjustment") -> tuple[str, ...]:
    """The CSV header of a protocol (an intensity staircase adds ``judgement`` before the timestamps)."""
    if protocol == "intensity" and method != "adjustment":
        head = _COLUMNS[protocol][: -len(_COMMON_TAIL)]
        return head + ("judgement",) + _COMMON_TAIL
    return _COLUMNS[protocol]


def stimulus_file(stimulus_id: str) -> str:
    """A stimulus' WAV relative to the session folder."""
    return f"stimuli/{stimulus_id}.wav"


def timestamp(when: datetime) -> str:
    """ISO 8601 in UTC with milliseconds: ``2026-03-01T10:15:02.123Z``."""
    return when.astimezone(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def parse_timestamp(text: str) -> datetime:
    """Read back :func:`timestamp` (``ValueError`` otherwise)."""
    if not text.endswith("Z"):
        raise ValueError(f"not a UTC timestamp: {text!r}")
    return datetime.fromisoformat(text[:-1] + "+00:00")


@dataclass(frozen=True)
class Answer:
    """What a participant answered in one trial.

    Attributes
    ----------
    value : float or None
        Intensity: the gain; dissimilarity: the rating 0..1.
    ratings : mapping of str to float
        Resynthesis: rating 0..1 of each version (``O``, ``S1``, ``S1:8``, ``S2:8``, ``M``).
    plays : int
        Times the trial's sound was played (1 = once when shown, no replay).
    slot_plays : mapping of str to int
        Resynthesis: plays of each version.
    reference_plays : int
        Plays of the reference (intensity: the equalisation reference; resynthesis: the original).
    judgement : str or None
        An intensity staircase: ``stronger`` or ``weaker`` (the test sine vs the reference); its
        ``value`` is then the gain the test sine played at.
    """

    value: float | None = None
    ratings: Mapping[str, float] = field(default_factory=dict)
    plays: int = 1
    slot_plays: Mapping[str, int] = field(default_factory=dict)
    reference_plays: int = 0
    judgement: str | None = None


def _number(name: str, value: object, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    if not low <= value <= high:
        raise ParameterError(f"{name} = {value:g} is outside [{low:g}, {high:g}]")
    return float(value)


def _count(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_PLAYS:
        raise ParameterError(f"{name} must be an integer 0..{MAX_PLAYS}, got {value!r}")
    return value


def _fmt(value: float, digits: int = 6) -> str:
    return f"{value:.{digits}g}" if math.isfinite(value) else str(value)


def make_row(
    protocol: Protocol,
    trial: Trial,
    answer: Answer,
    *,
    params: Mapping[str, Mapping[str, Any]],
    shown_at: datetime,
    answered_at: datetime,
    participant: str,
    gain_range: tuple[float, float] = (0.2, 5.0),
    reference: str = "reference",
    method: str = "adjustment",
) -> dict[str, str]:
    """The CSV row of an answered trial, validated.

    Parameters
    ----------
    protocol : str
    trial : Trial
        The plan's trial being answered.
    answer : Answer
    params : mapping of str to mapping
        Each stimulus' parameters (``level_db``, ``t1``...), by id.
    shown_at, answered_at : datetime
        When the trial was shown and answered (timezone-aware).
    participant : str
    gain_range : (float, float)
        Intensity: the allowed gains.
    reference : str
        Intensity: the reference's id.
    method : str
        Intensity: ``adjustment`` or a staircase (the row then has the ``judgement``).

    Returns
    -------
    row : dict of str to str
        Every column of :func:`columns`.

    Raises
    ------
    ParameterError
        An answer out of range or of the wrong kind; resynthesis ratings whose maximum is not 1
        (the protocol asks for the most similar version to be set to 1).
    """
    response = (answered_at - shown_at).total_seconds()
    common = {
        "trial": str(trial.index),
        "shown_at": timestamp(shown_at),
        "answered_at": timestamp(answered_at),
        "response_s": f"{max(response, 0.0):.3f}",
        "participant": participant,
    }
    if protocol == "intensity":
        gain = _number("gain", answer.value, *gain_range)
        sid = trial.stimuli[0]
        p = params[sid]
        row = {
            "stimulus": sid,
            "file": stimulus_file(sid),
            "gain": _fmt(gain),
            "log10_gain": _fmt(math.log10(gain)),
            "start_gain": _fmt(trial.start_gain or 1.0),
            "plays": str(_count("plays", answer.plays)),
            "reference_plays": str(_count("reference plays", answer.reference_plays)),
            "level_db": _fmt(p["level_db"]),
            "equalised_level_db": _fmt(p["level_db"] + 20.0 * math.log10(gain)),
            "broadband_db": _fmt(p["broadband_db"]),
            "t1": _fmt(p["t1"]),
            "reference": reference,
        }
        if method != "adjustment":
            if answer.judgement not in JUDGEMENTS:
                raise ParameterError(f"answer stronger or weaker, got {str(answer.judgement)[:20]!r}")
            row["judgement"] = answer.judgement
    elif protocol == "dissimilarity":
        rating = _number("rating", answer.value, 0.0, 1.0)
        a, b = trial.stimuli
        row = {
            "file_a": stimulus_file(a),
            "file_b": stimulus_file(b),
            "rating": _fmt(rating),
            "stimulus_a": a,
            "stimulus_b": b,
            "plays": str(_count("plays", answer.plays)),
            "t1_a": _fmt(params[a]["t1"]),
            "t1_b": _fmt(params[b]["t1"]),
            "level_db_a": _fmt(params[a]["level_db"]),
            "level_db_b": _fmt(params[b]["level_db"]),
        }
    else:
        if set(answer.ratings) != set(VERSIONS):
            raise ParameterError(f"rate all five versions ({', '.join(VERSIONS)}), got {sorted(answer.ratings)}")
        ratings = {
            v: _number(f"rating of slot {trial.slots.index(v) + 1}", answer.ratings[v], 0.0, 1.0) for v in VERSIONS
        }
        if max(ratings.values()) != 1.0:
            raise ParameterError("set the most similar version to 1 (the top of its slider)")
        original = trial.stimuli[0]
        row = {"original": original}
        row.update({f"slot_{k + 1}": v for k, v in enumerate(trial.slots)})
        row.update({f"rating_{v}": _fmt(ratings[v]) for v in VERSIONS})
        row.update({f"plays_{v}": str(_count(f"plays of {v}", answer.slot_plays.get(v, 0))) for v in VERSIONS})
        row.update(
            {
                "reference_plays": str(_count("reference plays", answer.reference_plays)),
                "t1": _fmt(params[original]["t1"]),
                "level_db": _fmt(params[original]["level_db"]),
            }
        )
    row.update(common)
    return {c: row[c] for c in columns(protocol, method)}


def check_row(protocol: Protocol, row: Mapping[str, str], trial: Trial) -> None:
    """Check a row read back from a session's CSV against the plan's trial.

    Raises
    ------
    ValueError
        The row is not this trial's (index, stimuli or slots differ) or an answer does not parse.
    """
    if row.get("trial") != str(trial.index):
        raise ValueError(f"trial {row.get('trial')!r} where trial {trial.index} was expected")
    if protocol == "intensity":
        ids: tuple[str, ...] = (row["stimulus"],)
        files: tuple[str, ...] = (row["file"],)
        gain = float(row["gain"])
        if not (math.isfinite(gain) and gain > 0):
            raise ValueError(f"gain {row['gain']} is not a positive number")
        if "judgement" in row and row["judgement"] not in JUDGEMENTS:
            raise ValueError(f"judgement {row['judgement'][:20]!r} is neither stronger nor weaker")
    elif protocol == "dissimilarity":
        ids = (row["stimulus_a"], row["stimulus_b"])
        files = (row["file_a"], row["file_b"])
        if not 0.0 <= float(row["rating"]) <= 1.0:
            raise ValueError(f"rating {row['rating']} outside 0..1")
    else:
        ids = (row["original"],)
        files = (stimulus_file(row["original"]),)
        slots = tuple(row[f"slot_{k}"] for k in range(1, 6))
        if slots != trial.slots:
            raise ValueError(f"slots {slots} differ from the plan's {trial.slots}")
        for v in VERSIONS:
            if not 0.0 <= float(row[f"rating_{v}"]) <= 1.0:
                raise ValueError(f"rating of {v} outside 0..1")
    if ids != trial.stimuli:
        raise ValueError(f"stimuli {', '.join(ids)} differ from the plan's {', '.join(trial.stimuli)}")
    if files != tuple(stimulus_file(s) for s in ids):
        raise ValueError(f"files {', '.join(files)} are not the stimuli's")
    parse_timestamp(row["shown_at"])
    parse_timestamp(row["answered_at"])
