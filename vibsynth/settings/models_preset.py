"""Presets and actuator profiles, typed: every key, its range, default and help text, in one place.

``docs/presets.md``'s key table and ``vibsynth/data/schema/preset.schema.json`` are generated
from :class:`PresetModel` (``python scripts/gen_settings_docs.py``).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator, ConfigDict, Field

from vibsynth.limits import GLIDE_MAX_MS as _GLIDE_MAX_MS
from vibsynth.settings.fields import SettingsModel, problem, setting
from vibsynth.settings.models_config import PROFILE_NAME, RESPONSE_POINTS, ResponsePoint

__all__ = [
    "PRESET_VERSION",
    "BALANCE_LIMIT",
    "GLIDE_MAX_MS",
    "NAME_PATTERN",
    "NAME_RULE",
    "TAG_PATTERN",
    "MAX_TAGS",
    "MAX_DESCRIPTION",
    "Tags",
    "TAGS_ALLOWED",
    "PresetModel",
    "ActuatorProfileModel",
]

#: The preset schema version this vibsynth writes (older files are migrated when read).
PRESET_VERSION = 1
#: Presets may hold balances beyond the database's +-1 (recordings outside it), up to this.
BALANCE_LIMIT = 4.0
#: The longest glide (:data:`vibsynth.limits.GLIDE_MAX_MS`), a float in the preset schema.
GLIDE_MAX_MS = float(_GLIDE_MAX_MS)
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
TAG_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9 _.-]{0,31}$"
MAX_TAGS = 16
MAX_DESCRIPTION = 4000
MAX_PROGRAM = 127

NAME_RULE = "1-64 letters, digits, '.', '_' or '-', starting with a letter or digit"
_TAG_RULE = "1-32 letters, digits, spaces, '.', '_' or '-'"


def _tags_list(value: Any) -> Any:
    if isinstance(value, str):
        raise problem(f"must be a list, e.g. tags: [{value}]")
    if value is not None and not isinstance(value, list):
        raise problem("must be a list of short words")
    return value


#: A list of tags (presets, clips): short words to find files by; null = none.
Tags = Annotated[
    Annotated[
        list[Annotated[str, Field(pattern=TAG_PATTERN, json_schema_extra={"x-allowed": _TAG_RULE})]],
        Field(max_length=MAX_TAGS),
    ]
    | None,
    BeforeValidator(_tags_list),
]
TAGS_ALLOWED = f"a list of up to {MAX_TAGS} tags ({_TAG_RULE})"


class PresetModel(SettingsModel):
    """A preset file: a named texture (schema version 1). Only ``intensity`` and ``balance`` are required."""

    model_config = ConfigDict(title="vibsynth preset")

    version: int = setting(
        PRESET_VERSION,
        "schema version; a file without it is version 0 and is migrated",
        ge=0,
        le=PRESET_VERSION,
    )
    name: str | None = setting(
        None,
        "the file name without .yaml (optional; if given it must match)",
        allowed=NAME_RULE,
        pattern=NAME_PATTERN,
    )
    description: str | None = setting("", "free text", allowed="text (a string)", max_length=MAX_DESCRIPTION)
    intensity: float = setting(
        ...,
        "knob 0..1: 0 = silent, (0, 1] spans knobs.range_db below knobs.ceiling_db of the 80-200 Hz band level",
        ge=0,
        le=1,
    )
    balance: float = setting(
        ...,
        "0 = the basis' mean spectrum, +1/-1 = 98th/2nd percentile of the database; live playback "
        "clamps to knobs.balance_min/max",
        unit="(knob units)",
        ge=-BALANCE_LIMIT,
        le=BALANCE_LIMIT,
    )
    glide_ms: Annotated[float, Field(ge=0, le=GLIDE_MAX_MS)] | None = setting(
        None, "glide when the preset is applied; null or absent = the channel's current glide", unit="ms"
    )
    program: Annotated[int, Field(ge=0, le=MAX_PROGRAM)] | None = setting(
        None, "MIDI program number (program change selects the preset)"
    )
    tags: Tags = setting([], "short words to find presets by", allowed=TAGS_ALLOWED)
    provenance: dict[str, Any] | None = setting(
        None, "free-form mapping: where the numbers came from", allowed="a mapping (e.g. recording: file.wav)"
    )


class ActuatorProfileModel(SettingsModel):
    """An actuator profile file: a named frequency response the bank equalises for."""

    model_config = ConfigDict(title="vibsynth actuator profile")

    name: str | None = setting(
        None,
        "the file name without .yaml (optional; if given it must match)",
        allowed="a profile name (letters, digits, . _ -)",
        pattern=PROFILE_NAME,
    )
    description: str = setting("", "what the actuator is", allowed="text (a string)")
    example: bool = setting(False, "true for an illustrative profile (not a measurement)")
    source: str = setting("", "where the points come from", allowed="text (a string)")
    response: Annotated[list[ResponsePoint], BeforeValidator(RESPONSE_POINTS.check)] = setting(
        ...,
        "[[Hz, dB], ...]: the actuator's response, interpolated on log-frequency",
        allowed=RESPONSE_POINTS.allowed(),
    )
    absolute: bool = setting(
        False,
        "true for a measured profile: response = recorded level per unit of drive through one sensor chain "
        "(devices measured with one sensor compare); false: a shape, 0 dB somewhere",
    )
    rate: Annotated[int, Field(ge=1000, le=384000)] | None = setting(
        None, "sample rate the response was measured at (null: not measured)", unit="Hz"
    )
    weighting: Annotated[list[ResponsePoint] | None, BeforeValidator(RESPONSE_POINTS.check)] = setting(
        None,
        "[[Hz, dB], ...]: the sensitivity weighting (response - iso-intensity curve, 0 dB at its top), or null",
        allowed=RESPONSE_POINTS.allowed(nullable=True),
    )
    band_hz: Annotated[list[Annotated[float, Field(gt=0, le=20000)]], Field(min_length=2, max_length=2)] | None = (
        setting(None, "[low, high]: the device's own intensity band; null = the paper's 80-200 Hz", unit="Hz")
    )
    provenance: dict[str, Any] | None = setting(
        None,
        "how it was measured: date, devices, channel, level, SNR, latency, sweeps, repeatability",
        allowed="a mapping",
    )
