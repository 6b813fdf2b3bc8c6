"""Command-line flags checked by the settings models: a flag that sets a key takes its range from the key.

::

    parser.add_argument("--channels", type=flag_type("audio.channels"), help=flag_help("audio.channels"))
    parser.add_argument("--output", choices=flag_choices("audio.backend"))
    parser.add_argument("--balance", type=flag_type("balance", PresetModel))

``vibsynth serve --channels 0`` then fails with ``0 is outside the allowed range [1, 64]``
from the same definition the config file is checked with.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

from pydantic import BaseModel

from vibsynth.settings.fields import JsonSchema, describe, explain, resolve
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.validation import model_spec

__all__ = ["flag_type", "flag_choices", "flag_help", "flag_range"]


def _kinds(schema: JsonSchema, defs: JsonSchema) -> set[str]:
    schema = resolve(schema, defs)
    out: set[str] = set()
    for option in schema.get("anyOf", [schema]):
        kind = option.get("type")
        if isinstance(kind, list):
            out.update(str(k) for k in kind)
        elif kind is not None:
            out.add(str(kind))
    return out


def _value(text: str, kinds: set[str]) -> Any:
    """The flag's text as the type the key takes (an index or a name for a device...)."""
    stripped = text.strip()
    if "integer" in kinds:
        try:
            return int(stripped)
        except ValueError:
            pass
    if "number" in kinds:
        try:
            return float(stripped)
        except ValueError:
            pass
    return text


def flag_type(key: str, model: type[BaseModel] = VibsynthConfig) -> Callable[[str], Any]:
    """An argparse ``type`` for a flag that sets ``key`` (dotted) of ``model``: converts and range-checks.

    Raises ``argparse.ArgumentTypeError`` (a usage error, exit code 2) with the key's range.
    """
    spec = model_spec(model)
    leaf = spec.leaves[key]
    kinds = _kinds(leaf.schema, spec.defs)

    def parse(text: str) -> Any:
        value = _value(text, kinds)
        reason = explain(leaf.schema, value, spec.defs)
        if reason is None:
            return value
        if reason == "must be finite":  # nan, inf: outside every range
            low, high = flag_range(key, model)
            if low is not None or high is not None:
                reason = "outside the allowed range " + describe(leaf.schema, spec.defs).split(" in ", 1)[-1]
        if reason.startswith("outside"):
            raise argparse.ArgumentTypeError(f"{text} is {reason}")
        raise argparse.ArgumentTypeError(f"{text!r} {reason} (allowed: {describe(leaf.schema, spec.defs)})")

    parse.__name__ = key  # argparse names the type in its messages
    return parse


def flag_choices(key: str, model: type[BaseModel] = VibsynthConfig) -> tuple[str, ...]:
    """The allowed words of a choice key (``audio.backend`` -> auto, sounddevice, null, wav)."""
    spec = model_spec(model)
    schema = resolve(spec.leaves[key].schema, spec.defs)
    values: list[str] = []
    for option in schema.get("anyOf", [schema]):
        values += [str(v) for v in option.get("enum", []) if v is not None]
    return tuple(dict.fromkeys(values))


def flag_range(key: str, model: type[BaseModel] = VibsynthConfig) -> tuple[float | None, float | None]:
    """``(low, high)`` of a numeric key (None where unbounded)."""
    spec = model_spec(model)
    schema = resolve(spec.leaves[key].schema, spec.defs)
    for option in schema.get("anyOf", [schema]):
        if option.get("type") in ("integer", "number"):
            low = option.get("minimum", option.get("exclusiveMinimum"))
            high = option.get("maximum", option.get("exclusiveMaximum"))
            return (None if low is None or math.isinf(low) else low), (None if high is None else high)
    return None, None


def flag_help(key: str, text: str = "", model: type[BaseModel] = VibsynthConfig) -> str:
    """Help of a flag that sets ``key``: ``text`` (default: the key's help) and the key's default and range."""
    spec = model_spec(model)
    leaf = spec.leaves[key]
    default = "" if leaf.required else f"; default: {key} = {leaf.default}"
    return f"{text or leaf.help} ({describe(leaf.schema, spec.defs)}{default})"
