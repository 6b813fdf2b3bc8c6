"""The ``follow:`` config section, typed: a sound or vibration in, the texture follows it live.

Added to the root model (:class:`~vibsynth.settings.models_config.VibsynthConfig`) with one
line; the ranges are the tracker's own limits (:mod:`vibsynth.dsp.follow.params`), declared
once there. docs/follow.md ("Live") explains what each key does. Example::

    follow:
      enabled: true
      device: "system:1,2"      # DEVICE[:CH,...] (1-based inputs), monitor, or a sound file
      mode: audio
      focus: effects
      routes:                   # stereo in: input 1 -> actuator 1, input 2 -> actuator 2
        - {channel: 1, inputs: [1]}
        - {channel: 2, inputs: [2], gain_db: -3}
        # or: the stereo balance pans touch source 1 between two points of the layout
        - {source: 1, inputs: [1, 2], pan: {left: [0, 0], right: [0.3, 0]}}
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field

from vibsynth.dsp.follow.params import (
    GAIN_DB_LIMITS,
    GATE_DB_LIMITS,
    RANGE_DB_LIMITS,
    TIME_MS_LIMITS,
    TrackerParams,
)
from vibsynth.settings.fields import Section, ValueModel, problem, setting
from vibsynth.settings.models_sources import MAX_SOURCES, POSITION_LIMIT_M

__all__ = ["MAX_ROUTES", "MAX_INPUT", "FADE_S_LIMITS", "PAN_RANGE_DB_LIMITS", "FollowPan", "FollowRoute", "Follow"]

#: Routes of ``follow.routes`` (one per output channel or source at most).
MAX_ROUTES = 64
#: Highest 1-based input channel a route may name (the input ring's channel limit).
MAX_INPUT = 64
#: ``follow.fade_s``: how long the output fades when the input is lost.
FADE_S_LIMITS = (0.0, 60.0)
#: ``pan.range_db``: the left/right level difference (dB) that puts a panned source at one end.
PAN_RANGE_DB_LIMITS = (1.0, 60.0)

_DEFAULTS = TrackerParams()
_Mode = Literal["vibration", "audio"]
_Focus = Literal["all", "effects", "bass", "beat"]
_Ms = Annotated[float, Field(ge=TIME_MS_LIMITS[0], le=TIME_MS_LIMITS[1])]
_Gate = Annotated[float, Field(ge=GATE_DB_LIMITS[0], le=GATE_DB_LIMITS[1])]
_Range = Annotated[float, Field(ge=RANGE_DB_LIMITS[0], le=RANGE_DB_LIMITS[1])]
_Input = Annotated[int, Field(ge=1, le=MAX_INPUT)]
_Coordinate = Annotated[float, Field(ge=-POSITION_LIMIT_M, le=POSITION_LIMIT_M)]
_POINT_ALLOWED = f"[x, y] or [x, y, z] in metres, each in [-{POSITION_LIMIT_M:g}, {POSITION_LIMIT_M:g}]"


class FollowPan(ValueModel):
    """``pan:`` of a source route with two inputs: the stereo balance moves the source between two points.

    The level difference of the two inputs, ``d = L - R`` in dB (each input's level measured like
    the route's tracker: the 80-200 Hz band in vibration mode, K-weighted in audio mode, over
    its balance window), puts the source at ``left + u (right - left)`` with
    ``u = 0.5 - d / (2 range_db)`` clipped to [0, 1]: only the first input -> ``left``, equal
    levels -> the middle, only the second -> ``right``.
    """

    left: Annotated[list[_Coordinate], Field(min_length=2, max_length=3)] = setting(
        ..., "where the source is when only the route's first input sounds", unit="m", allowed=_POINT_ALLOWED
    )
    right: Annotated[list[_Coordinate], Field(min_length=2, max_length=3)] = setting(
        ..., "where the source is when only the route's second input sounds", unit="m", allowed=_POINT_ALLOWED
    )
    range_db: float = setting(
        12.0,
        "left/right level difference that puts the source at one end (0 dB: the middle)",
        unit="dB",
        ge=PAN_RANGE_DB_LIMITS[0],
        le=PAN_RANGE_DB_LIMITS[1],
    )


class FollowRoute(ValueModel):
    """One entry of ``follow.routes``: which inputs drive an output channel (or a touch source), and how.

    A key left out takes the section's value; ``gain_db`` is added to the section's gain (so
    OSC ``/vibsynth/follow/gain`` still moves every route).
    """

    channel: Annotated[int, Field(ge=1)] | None = setting(None, "output channel (1-based); or give source")
    source: Annotated[int, Field(ge=1, le=MAX_SOURCES)] | None = setting(
        None, "touch source (1-based, needs a layout); or give channel"
    )
    inputs: Annotated[list[_Input], Field(min_length=1, max_length=MAX_INPUT)] | None = setting(
        None, "input channels (1-based) mixed (mean) into this route; null = every input"
    )
    mode: _Mode | None = setting(None, "vibration | audio; null = follow.mode")
    focus: _Focus | None = setting(None, "all | effects | bass | beat; null = follow.focus")
    gain_db: float = setting(
        0.0, "added to follow.gain_db for this route", unit="dB", ge=GAIN_DB_LIMITS[0], le=GAIN_DB_LIMITS[1]
    )
    gate_db: _Gate | None = setting(None, "null = follow.gate_db", unit="dB")
    range_db: _Range | None = setting(None, "null = follow.range_db", unit="dB")
    attack_ms: _Ms | None = setting(None, "null = follow.attack_ms", unit="ms")
    release_ms: _Ms | None = setting(None, "null = follow.release_ms", unit="ms")
    transients: bool | None = setting(None, "null = follow.transients")
    pan: FollowPan | None = setting(
        None,
        "a source route with two inputs: their stereo balance moves the source between pan.left and pan.right",
        allowed="null or {left: [x, y(, z)], right: [x, y(, z)], range_db: dB} (a source route with 2 inputs)",
    )


_ROUTES_ALLOWED = (
    "a list of {channel: N or source: K} with optional inputs (1-based list), mode, focus, gain_db, "
    "gate_db, range_db, attack_ms, release_ms, transients, pan (a source with 2 inputs)"
)


def _check_routes(value: Any) -> Any:
    """Each route names a channel or a source (not both), and no target twice."""
    if not isinstance(value, list):
        raise problem("must be a list of routes like {channel: 1, inputs: [1]}")
    if len(value) > MAX_ROUTES:
        raise problem(f"has {len(value)} routes; at most {MAX_ROUTES}")
    taken: dict[tuple[str, object], int] = {}
    for i, route in enumerate(value):
        if not isinstance(route, dict):
            continue  # the model says what a route must be
        if ("channel" in route) == ("source" in route):
            raise problem(f"item {i}: give either channel: N or source: K", i)
        key = ("channel", route["channel"]) if "channel" in route else ("source", route["source"])
        inputs = route.get("inputs")
        if isinstance(inputs, list) and len(set(map(repr, inputs))) != len(inputs):
            raise problem(f"item {i}: an input is listed twice in {inputs}", i, "inputs")
        if route.get("pan") is not None:
            if "source" not in route:
                raise problem(f"item {i}: pan moves a touch source: give source: K, not channel", i, "pan")
            if not (isinstance(inputs, list) and len(inputs) == 2):
                raise problem(f"item {i}: pan needs exactly two inputs (inputs: [L, R]), got {inputs!r}", i, "inputs")
        other = taken.setdefault(key, i)
        if other != i:
            raise problem(f"item {i}: {key[0]} {key[1]} is followed by item {other} already", i)
    return value


class Follow(Section):
    """``follow:``: follow a sound or vibration input live (docs/follow.md)."""

    enabled: bool = setting(False, "follow the input with serve (serve --follow turns it on)")
    device: str | None = setting(
        None,
        "DEVICE[:CH,...] (name substring or index, then 1-based inputs), monitor (what the system plays) "
        "or a sound file (WAV, FLAC, Ogg, MP3...); null = the default input",
        allowed="a device spec like 'system:1,2' or '3', monitor, a sound file path, or null",
        max_length=1024,
    )
    mode: _Mode = setting(_DEFAULTS.mode, "vibration: the input is a vibration; audio: program audio")
    focus: _Focus = setting(_DEFAULTS.focus, "audio mode: what shakes: all | effects | bass | beat")
    gain_db: float = setting(
        _DEFAULTS.gain_db,
        "added to the tracked level (vibration: output band level = input's + gain)",
        unit="dB",
        ge=GAIN_DB_LIMITS[0],
        le=GAIN_DB_LIMITS[1],
    )
    gate_db: _Gate | None = setting(
        None, "input level below which the output closes; null = the mode's default (audio -60, vibration -120)"
    )
    range_db: float = setting(
        _DEFAULTS.range_db,
        "audio mode: input loudness range spread over the intensity knob",
        unit="dB",
        ge=RANGE_DB_LIMITS[0],
        le=RANGE_DB_LIMITS[1],
    )
    attack_ms: float = setting(
        _DEFAULTS.attack_ms, "audio mode: level attack", unit="ms", ge=TIME_MS_LIMITS[0], le=TIME_MS_LIMITS[1]
    )
    release_ms: float = setting(
        _DEFAULTS.release_ms, "audio mode: level release", unit="ms", ge=TIME_MS_LIMITS[0], le=TIME_MS_LIMITS[1]
    )
    transients: bool = setting(_DEFAULTS.transients, "onsets play as short intensity bursts (clip transients)")
    on_loss: Literal["hold", "fade"] = setting(
        "fade", "when the input is lost: hold the last texture, or fade it out over fade_s"
    )
    fade_s: float = setting(1.0, "fade of a lost input", unit="s", ge=FADE_S_LIMITS[0], le=FADE_S_LIMITS[1])
    routes: Annotated[list[FollowRoute], BeforeValidator(_check_routes)] = setting(
        [],
        "per output channel or source: inputs and overrides; [] = every channel follows "
        "(input n -> channel n when the counts agree, else the mix of all inputs)",
        allowed=_ROUTES_ALLOWED,
    )
