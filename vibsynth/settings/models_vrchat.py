"""The ``vrchat:`` config section: VRChat avatar parameters driving sources, channels, presets and clips (docs/vr.md).

Example::

    vrchat:
      enabled: true
      parameters:
        - {name: ChestL, source: 1, at: [-0.1, 0.25], preset: velvet, drive: level}
        - {name: ChestR, source: 2, at: [0.1, 0.25], preset: gravel, drive: velocity}
        - {name: Spine, source: 3, moving: [[-0.15, 0.15], [0.15, 0.15]], preset: velvet}
        - {name: Slap, clip: impact}            # a bool: its rising edge plays the clip
        - {name: Hug, channel: 2, preset: towel}
        - {name: Wet, preset: rain, threshold: 0.5}
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field

from vibsynth.limits import MAX_CHANNELS
from vibsynth.settings.fields import Section, ValueModel, problem, setting
from vibsynth.settings.models_sources import MAX_SOURCES, POSITION_LIMIT_M

__all__ = ["PARAMETER_NAME", "MAX_PARAMETERS", "AvatarParameter", "Vrchat", "target_of"]

#: An avatar parameter's name as it appears in ``/avatar/parameters/NAME``: printable, no space,
#: no OSC pattern character (VRChat names may hold ``/``, e.g. ``Go/Float``).
PARAMETER_NAME = r"^[^\s#*,?\[\]{}\x00-\x1f]{1,128}$"
#: Mapped parameters at most (a VRChat avatar has 256 synced bits; this bounds the table anyway).
MAX_PARAMETERS = 256

_Coord = Annotated[float, Field(ge=-POSITION_LIMIT_M, le=POSITION_LIMIT_M)]
_Point = Annotated[list[_Coord], Field(min_length=2, max_length=3)]
_TARGETS = ("source", "channel", "clip")


class AvatarParameter(ValueModel):
    """One entry of ``vrchat.parameters``: an avatar parameter and what it drives."""

    name: str = setting(..., "the avatar parameter (/avatar/parameters/NAME)", pattern=PARAMETER_NAME)
    source: int | None = setting(None, "drive this touch source (1-16; needs a layout)", ge=1, le=MAX_SOURCES)
    channel: int | None = setting(
        None, "drive this channel's knobs (or, with clip, play the clip there)", ge=1, le=MAX_CHANNELS
    )
    clip: str | None = setting(
        None, "play this clip on a rising edge / threshold crossing", min_length=1, max_length=128
    )
    preset: str | None = setting(
        None,
        "the texture the source or channel plays; alone: loaded on every channel at a threshold crossing",
        min_length=1,
        max_length=128,
    )
    at: _Point | None = setting(None, "the source's position [x, y(, z)]", unit="m")
    moving: Annotated[list[_Point], Field(min_length=2, max_length=2)] | None = setting(
        None, "[[x, y], [x, y]]: the value 0..1 moves the source from the first point to the second", unit="m"
    )
    drive: Literal["level", "velocity"] = setting(
        "level", "level: the value is the intensity (held); velocity: its rate of change is (fades when still)"
    )
    threshold: float = setting(
        0.0, "a source is on above it; a clip or preset fires when the value rises across it", ge=-1e6, le=1e6
    )


def target_of(entry: dict[str, Any] | AvatarParameter) -> str:
    """What an entry drives: ``source``, ``channel``, ``clip`` or ``preset`` (``""`` when it names none)."""
    get = entry.get if isinstance(entry, dict) else lambda key: getattr(entry, key)
    for key in ("source", "clip", "channel", "preset"):
        if get(key) is not None:
            return key
    return ""


def _check_parameters(value: Any) -> Any:
    """One target per entry, a position only for a source (a fixed point or a path), names unique."""
    if not isinstance(value, list):
        raise problem("must be a list like [{name: ChestL, source: 1, at: [-0.1, 0.25], preset: velvet}]")
    if len(value) > MAX_PARAMETERS:
        raise problem(f"has {len(value)} entries; at most {MAX_PARAMETERS}")
    seen: dict[str, int] = {}
    for i, entry in enumerate(value):
        if not isinstance(entry, dict):
            continue  # the model says what an entry must be
        name = entry.get("name")
        if isinstance(name, str):
            if name in seen:
                raise problem(f"item {i}: parameter {name!r} is mapped by item {seen[name]} already", i, "name")
            seen[name] = i
        given = [key for key in _TARGETS if entry.get(key) is not None]
        if given == ["channel", "clip"]:
            given = ["clip"]  # the clip plays on that channel
        if len(given) > 1:
            raise problem(f"item {i}: drives one thing: give source, channel or clip, not {' and '.join(given)}", i)
        if not given and entry.get("preset") is None:
            raise problem(f"item {i}: drives nothing: give source, channel, clip or preset", i)
        is_source = given == ["source"]
        if is_source and (entry.get("at") is None) == (entry.get("moving") is None):
            raise problem(f"item {i}: a source is at a point (at: [x, y]) or moving (moving: [[x, y], [x, y]])", i)
        for key in ("at", "moving"):
            if not is_source and entry.get(key) is not None:
                raise problem(f"item {i}: {key} places a source; give source: 1-{MAX_SOURCES}", i, key)
        if entry.get("drive") == "velocity" and (given in (["clip"], []) or target_of(entry) == "preset"):
            raise problem(f"item {i}: drive velocity needs a source or a channel", i, "drive")
    return value


class Vrchat(Section):
    """``vrchat:``: VRChat avatar parameters (Contact Receivers) driving the synthesizer (docs/vr.md)."""

    enabled: bool = setting(False, "take VRChat's avatar parameters (/avatar/parameters/..., /avatar/change)")
    host: str = setting(
        "127.0.0.1",
        "where VRChat runs when it is not found over mDNS (its OSCQuery HOST_INFO says otherwise)",
        allowed="a host name or IP address",
        pattern=r"^\S+$",
    )
    send_port: int = setting(9000, "VRChat's OSC input port when not found over mDNS", ge=1, le=65535)
    listen_port: int = setting(
        9001,
        "also listen here (on localhost): VRChat's OSC output port for apps it does not find over OSCQuery; 0 = off",
        ge=0,
        le=65535,
    )
    velocity_fade_ms: float = setting(
        300.0,
        "a velocity drive fades to silence over this once its parameter stops changing",
        unit="ms",
        gt=0,
        le=10000,
    )
    velocity_full: float = setting(
        4.0, "rate of change (value units per second) that gives a velocity drive its full intensity", gt=0, le=1000
    )
    velocity_brightness: float = setting(
        1.0, "balance added at full velocity (faster = brighter)", unit="(knob units)", ge=-6, le=6
    )
    parameters: Annotated[list[AvatarParameter], BeforeValidator(_check_parameters)] = setting(
        [],
        "avatar parameters -> what they drive",
        allowed="a list of {name, source (with at or moving) | channel | clip | preset, preset, drive, threshold}",
    )
