"""Checks of the structured setting values (point lists, channel lists, MIDI bindings), with exact messages.

JSON Schema says most of what these values may be (and the models declare it); what it
cannot say (points strictly increasing, a binding with either a cc or an nrpn, IP networks)
is checked here, before pydantic's own checks, so the message names the item and the rule.
Each check takes the raw value and returns it unchanged, or raises
:func:`~vibsynth.settings.fields.problem`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from vibsynth.errors import ConfigError
from vibsynth.settings.fields import JsonSchema, fmt_number, is_int, is_number, problem

__all__ = [
    "Points",
    "check_channel_list",
    "check_allow_list",
    "check_midi_channel_map",
    "check_bindings",
    "check_nrpn_map",
    "NRPN_MAX",
    "CC_MAX",
    "BINDABLE_CC_MAX",
    "MIDI_CHANNELS",
    "KNOB_BALANCE_LIMIT",
]

NRPN_MAX = 16383
CC_MAX = 127
#: Highest controller a knob may be bound to: CC 120-127 are channel mode messages (all sound
#: off, reset controllers, all notes off, ...) that the mapper handles itself.
BINDABLE_CC_MAX = 119
MIDI_CHANNELS = 16
#: The live balance range (knobs.balance_min/max) may be set at most this far out; clips hold
#: balances within it.
KNOB_BALANCE_LIMIT = 10.0
_BINDING_KEYS = {"cc": (0, BINDABLE_CC_MAX), "channel": (1, MIDI_CHANNELS)}


@dataclass(frozen=True)
class Points:
    """A list of ``[x, value]`` pairs with x increasing (a response curve, a speed curve).

    The one description of such a list: :meth:`check` (the validator) and :meth:`schema`
    (its JSON Schema) both come from these numbers.
    """

    x_name: str
    x_low: float
    x_low_open: bool
    y_name: str
    y_low: float
    y_high: float
    min_points: int

    def allowed(self, *, nullable: bool = False) -> str:
        lo = "(" if self.x_low_open else "["
        return (
            f"a list of at least {self.min_points} pairs [{self.x_name}, {self.y_name}] with {self.x_name} in "
            f"{lo}{fmt_number(self.x_low)}, inf) strictly increasing and {self.y_name} in "
            f"[{fmt_number(self.y_low)}, {fmt_number(self.y_high)}]" + (", or null" if nullable else "")
        )

    def pair_schema(self) -> JsonSchema:
        x: JsonSchema = {"type": "number", ("exclusiveMinimum" if self.x_low_open else "minimum"): self.x_low}
        return {"prefixItems": [x, {"type": "number", "minimum": self.y_low, "maximum": self.y_high}]}

    def check(self, value: Any) -> Any:
        if value is None:
            return value
        if not isinstance(value, list):
            raise problem("must be a list of pairs")
        if len(value) < self.min_points:
            raise problem(f"needs at least {self.min_points} points")
        lo = "(" if self.x_low_open else "["
        previous: float | None = None
        for i, point in enumerate(value):
            if not (isinstance(point, list) and len(point) == 2 and all(is_number(v) for v in point)):
                raise problem(f"item {i} ({point!r}) is not a pair of numbers")
            x, y = float(point[0]), float(point[1])
            if not (math.isfinite(x) and math.isfinite(y)):
                raise problem(f"item {i} ({point!r}) is not finite")
            if x < self.x_low or (self.x_low_open and x == self.x_low):
                raise problem(f"item {i}: {self.x_name} {x:g} is outside {lo}{fmt_number(self.x_low)}, inf)")
            if not self.y_low <= y <= self.y_high:
                raise problem(f"item {i}: value {y:g} is outside [{fmt_number(self.y_low)}, {fmt_number(self.y_high)}]")
            if previous is not None and x <= previous:
                raise problem(f"item {i}: {self.x_name} {x:g} does not increase (previous {previous:g})")
            previous = x
        return value


def check_channel_list(value: Any) -> Any:
    """``audio.channel_map``: null or a non-empty list of distinct 1-based device outputs."""
    if value is None:
        return value
    if not isinstance(value, list) or not value:
        raise problem("must be a non-empty list of device outputs (1-based integers)")
    if not all(is_int(v) and v >= 1 for v in value):
        raise problem("every entry must be an integer >= 1 (device outputs are 1-based)")
    if len(set(value)) != len(value):
        raise problem("lists a device output twice")
    return value


def check_allow_list(value: Any) -> Any:
    """``osc.allow``: checked by the OSC server's own parser, so what passes here starts the server."""
    from vibsynth.settings.allow_list import parse_allow_list

    try:
        parse_allow_list(value)
    except ConfigError as exc:
        raise problem(str(exc)) from None
    return value


def check_midi_channel_map(value: Any) -> Any:
    """``midi.channel_map``: {MIDI channel 1-16: 'all' or a non-empty list of actuator channels}."""
    if not isinstance(value, dict) or not value:
        raise problem("must be a mapping {MIDI channel 1-16: 'all' or [actuator channels]}")
    for key, target in value.items():
        if not (is_int(key) and 1 <= key <= MIDI_CHANNELS):
            raise problem(f"key {key!r} is not a MIDI channel 1..{MIDI_CHANNELS}")
        if target == "all":
            continue
        if not (isinstance(target, list) and target and all(is_int(t) and t >= 1 for t in target)):
            raise problem(f"channel {key}: {target!r} must be 'all' or a list of actuator channels (1-based)")
    return value


def _nrpn_problem(value: Any) -> str | None:
    """An NRPN number: 0..16383, or [msb, lsb] with each 0..127."""
    if is_int(value) and 0 <= value <= NRPN_MAX:
        return None
    if isinstance(value, list) and len(value) == 2 and all(is_int(v) and 0 <= v <= CC_MAX for v in value):
        return None
    return f"nrpn {value!r} must be 0..{NRPN_MAX} or [msb, lsb] with each 0..{CC_MAX}"


def check_bindings(value: Any) -> Any:
    """``midi.mapping.<knob>``: a list of {cc: N} or {nrpn: N}, with optional channel, invert, range."""
    if not isinstance(value, list):
        raise problem("must be a list of bindings like {cc: 74} or {nrpn: [1, 0]}")
    for i, item in enumerate(value):
        if not isinstance(item, dict) or ("cc" in item) == ("nrpn" in item):
            raise problem(f"item {i} ({item!r}) must be a mapping with either a cc or an nrpn number, e.g. {{cc: 74}}")
        for key, val in item.items():
            if key == "invert":
                if not isinstance(val, bool):
                    raise problem(f"item {i}: invert must be true or false")
            elif key == "nrpn":
                reason = _nrpn_problem(val)
                if reason:
                    raise problem(f"item {i}: {reason}")
            elif key == "range":
                if not (
                    isinstance(val, list)
                    and len(val) == 2
                    and all(is_number(v) and math.isfinite(v) for v in val)
                    and val[0] < val[1]
                ):
                    raise problem(f"item {i}: range {val!r} must be [low, high] with finite low < high")
            elif key not in _BINDING_KEYS:
                raise problem(f"item {i}: unknown key {key!r} (allowed: cc, nrpn, channel, invert, range)")
            else:
                lo, hi = _BINDING_KEYS[key]
                if not (is_int(val) and lo <= val <= hi):
                    raise problem(f"item {i}: {key} {val!r} is outside [{lo}, {hi}]")
    return value


def check_nrpn_map(value: Any) -> Any:
    """``midi.nrpn``: {intensity: [msb, lsb], balance: [msb, lsb]} (or 0..16383)."""
    if not isinstance(value, dict):
        raise problem("must be a mapping {intensity: [msb, lsb], balance: [msb, lsb]}")
    for knob, number in value.items():
        if knob not in ("intensity", "balance"):
            raise problem(f"unknown knob {knob!r} (allowed: intensity, balance)")
        reason = _nrpn_problem(number)
        if reason:
            raise problem(f"{knob}: {reason}")
    return value


def null_means(text: str) -> Callable[[Any], Any]:
    """YAML's unquoted ``null`` read as the string ``text`` (``audio.backend: null`` is the null backend)."""

    def convert(value: Any) -> Any:
        return text if value is None else value

    return convert
