"""The typed settings of vibsynth, one definition of every key: config, presets, actuator profiles, layouts.

Each key is declared once (type, range or choices, default, one-line help) in
:mod:`vibsynth.settings.models_config` (the config file, its layout section) and
:mod:`vibsynth.settings.models_preset` (presets, actuator profiles). Validation messages,
the docs' key tables, the JSON Schemas, command-line flag checks and the defaults used
elsewhere (:func:`default_of`, :func:`bounds_of`) all come from there.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel

from vibsynth.settings.models_config import (
    CONFIG_VERSION,
    Actuator,
    Audio,
    Bank,
    ChannelPosition,
    Knobs,
    Midi,
    MidiBinding,
    MidiMapping,
    NrpnNumbers,
    Osc,
    Presets,
    Speed,
    VibsynthConfig,
)
from vibsynth.settings.models_preset import (
    BALANCE_LIMIT,
    GLIDE_MAX_MS,
    PRESET_VERSION,
    ActuatorProfileModel,
    PresetModel,
)
from vibsynth.settings.validation import model_spec

__all__ = [
    "CONFIG_VERSION",
    "PRESET_VERSION",
    "BALANCE_LIMIT",
    "GLIDE_MAX_MS",
    "VibsynthConfig",
    "Audio",
    "Bank",
    "Knobs",
    "Actuator",
    "Osc",
    "Midi",
    "MidiBinding",
    "MidiMapping",
    "NrpnNumbers",
    "Speed",
    "Presets",
    "ChannelPosition",
    "PresetModel",
    "ActuatorProfileModel",
    "default_of",
    "bounds_of",
]


def default_of(key: str, model: type[BaseModel] = VibsynthConfig) -> Any:
    """The default of a dotted key, as plain data (e.g. ``default_of("knobs.balance_min")`` is -3.5)."""
    return model_spec(model).leaves[key].default


def bounds_of(key: str, model: type[BaseModel] = VibsynthConfig) -> tuple[float | None, float | None]:
    """The numeric range ``(low, high)`` of a dotted key (None where unbounded), e.g. ``(0, 10000)``."""
    spec = model_spec(model)
    schema = spec.leaves[key].schema
    for option in schema.get("anyOf", [schema]):
        if option.get("type") in ("integer", "number"):
            low = option.get("minimum", option.get("exclusiveMinimum"))
            high = option.get("maximum", option.get("exclusiveMaximum"))
            return low, high
    raise KeyError(f"{key} is not a number")
