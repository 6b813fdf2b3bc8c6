"""The three protocols of the paper's "Experiments" and their parameters, checked at the edge.

* ``intensity`` (experiment 1): the participant adjusts each stimulus' gain (0.2-5) until it
  feels as intense as a reference.
* ``dissimilarity`` (experiment 2): all pairs, self-pairs included, in random order, each
  played as stimulus - 500 ms silence - stimulus and rated 0 (very similar) .. 1 (very
  dissimilar), after a familiarisation block of 30 random pairs that is not saved.
* ``resynthesis`` (experiment 3): per original, 5 versions (the original as a hidden
  reference, S1, S1:8, S2:8, M) on 5 sliders in random positions, rated 0 (very
  dissimilar) .. 1 (very similar), the most similar set to 1.

The defaults of :class:`LabParameters` are the paper's; the ``lab:`` config section
(:class:`vibsynth.settings.models_lab.Lab`) sets them.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from typing import Any, Literal

from vibsynth.errors import ParameterError
from vibsynth.settings.models_lab import Lab, lab_range

__all__ = [
    "PROTOCOLS",
    "Protocol",
    "VERSIONS",
    "VERSION_TAGS",
    "MAX_SEED",
    "PARTICIPANT_RULE",
    "LabParameters",
    "check_protocol",
    "check_participant",
    "check_seed",
]

Protocol = Literal["intensity", "dissimilarity", "resynthesis"]
PROTOCOLS: tuple[Protocol, ...] = ("intensity", "dissimilarity", "resynthesis")

#: Experiment 3's versions of an original, in the paper's order: O (the original itself, the
#: hidden reference), S1 (M + t1 V1), S1:8 (all 8 components), S2:8 (all but the first), M (the
#: database's mean spectrum, the anchor).
VERSIONS: tuple[str, ...] = ("O", "S1", "S1:8", "S2:8", "M")
#: The same versions as they appear in stimulus ids and file names (no ':').
VERSION_TAGS: dict[str, str] = {"O": "O", "S1": "S1", "S1:8": "S1-8", "S2:8": "S2-8", "M": "M"}

#: Seeds are integers 0 .. 2**64 - 1 (numpy takes any size; a bound keeps a typed seed readable,
#: storable in JSON and CSV as it is, and free of a huge-number parse).
MAX_SEED = 2**64 - 1
#: A participant id: letters, digits, '_' and '-', starting with a letter or digit, at most 64
#: characters. It names a folder, so nothing that could walk out of it ('/', '\\', '..', ':').
PARTICIPANT_RULE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")


def check_protocol(name: object) -> Protocol:
    """The protocol named ``name``; a :class:`ParameterError` listing the three otherwise."""
    for protocol in PROTOCOLS:
        if name == protocol:
            return protocol
    raise ParameterError(f"unknown protocol {name!r}; choose one of {', '.join(PROTOCOLS)}")


def check_participant(text: object) -> str:
    """A participant id that is safe as (part of) a folder name.

    Raises
    ------
    ParameterError
        Not a string, empty, too long, or with characters other than letters, digits, '_' and '-'
        (path separators, '..', spaces, control characters).
    """
    if not isinstance(text, str) or PARTICIPANT_RULE.fullmatch(text) is None:
        shown = repr(text)[:80]
        raise ParameterError(
            f"participant id {shown} is not allowed: use 1-64 letters, digits, '_' or '-', "
            "starting with a letter or digit (it names the session folder)"
        )
    return text


def check_seed(value: object) -> int:
    """A seed as an int 0 .. :data:`MAX_SEED`, from an int or its decimal text.

    Raises
    ------
    ParameterError
        Not an integer (a bool, a float, text that is not decimal digits), negative, or too large.
    """
    if isinstance(value, bool):
        raise ParameterError(f"seed must be an integer 0..{MAX_SEED}, got {value!r}")
    if isinstance(value, str):
        text = value.strip()
        if not text.isdecimal() or not text.isascii() or len(text) > len(str(MAX_SEED)):
            raise ParameterError(f"seed must be an integer 0..{MAX_SEED}, got {value[:40]!r}")
        value = int(text)
    if not isinstance(value, int) or not 0 <= value <= MAX_SEED:
        shown = repr(value) if not isinstance(value, int) or value.bit_length() < 256 else "a huge number"
        raise ParameterError(f"seed must be an integer 0..{MAX_SEED}, got {shown}")
    return value


@dataclass(frozen=True)
class LabParameters:
    """What a session is run with; the defaults are the paper's.

    Attributes
    ----------
    stimulus_s : float
        Duration of each stimulus (paper: 1 s).
    gap_s : float
        Silence between the two stimuli of a pair (paper: 0.5 s).
    familiarisation_pairs : int
        Random pairs before the dissimilarity test, not saved (paper: 30).
    gain_min, gain_max : float
        Range of the intensity equalisation's gain (paper: 0.2 and 5; the reference has gain 1).
    level : float
        Intensity knob at which a stimulus set's median stimulus plays.
    """

    stimulus_s: float = 1.0
    gap_s: float = 0.5
    familiarisation_pairs: int = 30
    gain_min: float = 0.2
    gain_max: float = 5.0
    level: float = 0.75

    def __post_init__(self) -> None:
        # (field, value, lab: key, scale): the ranges are the lab: section's (one definition).
        checks = (
            ("stimulus_s", self.stimulus_s, "stimulus_s", 1.0),
            ("gap_s", self.gap_s, "gap_ms", 1e-3),
            ("gain_min", self.gain_min, "gain_min", 1.0),
            ("gain_max", self.gain_max, "gain_max", 1.0),
            ("level", self.level, "level", 1.0),
        )
        for name, value, key, scale in checks:
            low, high, low_open = lab_range(key)
            low, high = low * scale, high * scale
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
                or (value <= low if low_open else value < low)
                or value > high
            ):
                span = f"{'(' if low_open else '['}{low:g}, {high:g}]"
                raise ParameterError(f"{name} must be a number in {span}, got {value!r}")
        if self.gain_min >= self.gain_max:
            raise ParameterError(f"gain_min ({self.gain_min:g}) must be below gain_max ({self.gain_max:g})")
        if isinstance(self.familiarisation_pairs, bool) or not isinstance(self.familiarisation_pairs, int):
            raise ParameterError(f"familiarisation_pairs must be an integer, got {self.familiarisation_pairs!r}")
        low, high, _ = lab_range("familiarisation_pairs")
        if not low <= self.familiarisation_pairs <= high:
            raise ParameterError(
                f"familiarisation_pairs must be in [{low:g}, {high:g}], got {self.familiarisation_pairs}"
            )

    @classmethod
    def from_settings(cls, lab: Lab, **overrides: Any) -> LabParameters:
        """From the typed ``lab:`` section, with per-session overrides.

        Parameters
        ----------
        lab : Lab
            ``settings.lab``.
        **overrides
            Fields of this class; ``None`` values are ignored.
        """
        values: dict[str, Any] = {
            "stimulus_s": lab.stimulus_s,
            "gap_s": lab.gap_ms / 1000.0,
            "familiarisation_pairs": lab.familiarisation_pairs,
            "gain_min": lab.gain_min,
            "gain_max": lab.gain_max,
            "level": lab.level,
        }
        values.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for session.json)."""
        return asdict(self)
