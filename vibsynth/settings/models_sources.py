"""The typed ``sources:`` section: touch sources mixed onto the layout's actuators (docs/vr.md).

Defaults of new sources, the limits every control (OSC, MIDI) is checked against, the mixer's
update period and the MIDI controllers bound to source positions.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field
from pydantic_core import PydanticCustomError

from vibsynth.limits import GLIDE_MAX_MS
from vibsynth.settings.fields import Section, ValueModel, cross_problem, is_int, problem, setting
from vibsynth.settings.values import BINDABLE_CC_MAX, MIDI_CHANNELS

__all__ = [
    "MAX_SOURCES",
    "ROLLOFF_NAMES",
    "POSITION_LIMIT_M",
    "PositionCc",
    "SourceMidi",
    "Sources",
    "knob_conflict",
]

#: Sources addressable at once (``/vibsynth/source/1..16/...``).
MAX_SOURCES = 16
#: The roll-off laws (vibsynth.dsp.spatial.ROLLOFFS; a test keeps both equal).
ROLLOFF_NAMES = ("linear", "smooth", "inverse-square", "phantom")
#: Source coordinates lie within +-this, like the layout's (metres).
POSITION_LIMIT_M = 10.0

_AXES = ("x", "y", "z")
#: Controllers that carry NRPN/RPN data (6, 38, 96-101): never bound (as for the knobs).
_RESERVED_CCS = frozenset({6, 38, 96, 97, 98, 99, 100, 101})


class PositionCc(ValueModel):
    """A MIDI controller moving one coordinate of a source: ``{cc: 20, range: [-0.1, 0.1]}``."""

    cc: int = setting(..., "controller number (120-127 are channel mode messages)", ge=0, le=BINDABLE_CC_MAX)
    channel: Annotated[int, Field(ge=1, le=MIDI_CHANNELS)] | None = setting(
        None, "MIDI channel 1-16 (null = every channel)"
    )
    range: Annotated[
        list[Annotated[float, Field(ge=-POSITION_LIMIT_M, le=POSITION_LIMIT_M)]], Field(min_length=2, max_length=2)
    ] = setting([-0.1, 0.1], "[low, high] coordinate at the controller's 0 and 127", unit="m")


class SourceMidi(ValueModel):
    """One source's coordinates bound to MIDI controllers (``x``, ``y`` and optionally ``z``)."""

    source: int = setting(..., "the source, 1-based as in OSC addresses", ge=1, le=MAX_SOURCES)
    x: PositionCc | None = setting(None, "controller of x")
    y: PositionCc | None = setting(None, "controller of y")
    z: PositionCc | None = setting(None, "controller of z")


def _check_source_midi(value: Any) -> Any:
    """``sources.midi``: a list of {source: k, x: {cc: N}, y: {cc: M}}; a controller moves one coordinate."""
    if not isinstance(value, list):
        raise problem("must be a list like [{source: 1, x: {cc: 20}, y: {cc: 21}}]")
    used: dict[tuple[int, int | None], str] = {}
    for i, item in enumerate(value):
        if not isinstance(item, dict):
            continue  # the model says what it must be
        if not any(axis in item for axis in _AXES):
            raise problem(f"item {i}: binds no coordinate (give x, y or z)", i)
        for axis in _AXES:
            binding = item.get(axis)
            if not isinstance(binding, dict) or not is_int(binding.get("cc")):
                continue
            if binding["cc"] in _RESERVED_CCS:
                raise problem(f"item {i}: {axis}.cc {binding['cc']} is reserved for NRPN/RPN data", i, axis)
            key = (binding["cc"], binding.get("channel"))
            here = f"source {item.get('source')} {axis}"
            if key in used:
                raise problem(f"item {i}: cc {key[0]} moves {used[key]} already", i, axis)
            used[key] = here
            bounds = binding.get("range")
            if isinstance(bounds, list) and len(bounds) == 2 and bounds[0] == bounds[1]:
                raise problem(f"item {i}: {axis}.range {bounds} must span some distance", i, axis)
    return value


class Sources(Section):
    """``sources:``: touch sources mixed onto the layout's actuators (docs/vr.md)."""

    radius: float = setting(
        0.05,
        "radius of a new source; the largest radius a control may set is this key's upper bound",
        unit="m",
        gt=0,
        le=POSITION_LIMIT_M,
    )
    rolloff: Literal["linear", "smooth", "inverse-square", "phantom"] = setting(
        "smooth", "roll-off law of a new source: linear, smooth, inverse-square or phantom"
    )
    glide_ms: float = setting(
        20.0, "a position message glides there over this time, 0 = jump", unit="ms", ge=0, le=GLIDE_MAX_MS
    )
    update_ms: float = setting(
        10.0,
        "while a source moves, the mix is recomputed this often (channels glide in between)",
        unit="ms",
        ge=2,
        le=100,
    )
    speed: bool = setting(False, "new sources take their intensity from their speed through speed.curve")
    speed_window_ms: float = setting(
        100.0,
        "a source's speed is measured over its positions of this long; none in it = at rest",
        unit="ms",
        ge=10,
        le=2000,
    )
    schedule_capacity: int = setting(
        1024,
        "most timetagged source messages waiting at once; more are refused with an error reply",
        ge=1,
        le=100_000,
    )
    midi: Annotated[list[SourceMidi], BeforeValidator(_check_source_midi)] = setting(
        [],
        "MIDI controllers bound to source coordinates",
        allowed="a list like [{source: 1, x: {cc: 20, range: [-0.1, 0.1]}, y: {cc: 21}}] (optional channel 1-16)",
    )


def knob_conflict(sources: Sources, mapping: Any) -> PydanticCustomError | None:
    """A controller of ``sources.midi`` that ``midi.mapping`` (its ``intensity``/``balance`` lists) binds to a knob.

    Two bindings clash when their cc is equal and their MIDI channels may be equal (null = every channel).
    """
    for i, item in enumerate(sources.midi):
        for axis in _AXES:
            binding: PositionCc | None = getattr(item, axis)
            if binding is None:
                continue
            for knob in ("intensity", "balance"):
                for other in getattr(mapping, knob):
                    if (
                        other.cc == binding.cc
                        and None in (other.channel, binding.channel)
                        or (other.cc == binding.cc and other.channel == binding.channel)
                    ):
                        return cross_problem(
                            f"sources.midi[{i}].{axis}: cc {binding.cc} is bound to midi.mapping.{knob} too "
                            "(allowed: a controller moves one thing; give one of them another cc or MIDI channel)",
                            "sources.midi",
                            "midi.mapping",
                        )
    return None
