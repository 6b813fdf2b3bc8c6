"""Building blocks of the settings models: one helper to declare a setting, and the texts made from it.

Every setting is declared once, with :func:`setting` (default, help text, unit, range or
choices as pydantic constraints). Everything else is derived from that declaration through
the field's JSON Schema:

* :func:`describe` - what is allowed, in words (``an integer in [2400, 384000] Hz``), for
  error messages, the generated docs tables and command-line flags;
* :func:`explain` - why a value is not allowed (``outside the allowed range [0, 1]``), phrased
  like every vibsynth error;
* :func:`problem` - the error a custom validator raises, with an exact message.
"""

from __future__ import annotations

import math
import re
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, SerializerFunctionWrapHandler, model_serializer
from pydantic_core import PydanticCustomError

from vibsynth.settings.yamldoc import short_repr

__all__ = [
    "SettingsModel",
    "Section",
    "ValueModel",
    "setting",
    "problem",
    "cross_problem",
    "describe",
    "resolve",
    "alternatives",
    "explain",
    "show",
    "fmt_number",
    "is_number",
    "is_int",
    "JsonSchema",
]

JsonSchema = dict[str, Any]

#: Error type of :func:`problem` (a message written for people, with an optional inner path).
PROBLEM = "vibsynth"
#: Error type of :func:`cross_problem` (a rule between several keys).
CROSS_PROBLEM = "vibsynth_cross"


class SettingsModel(BaseModel):
    """Base of every settings model: unknown keys are errors, types are strict, numbers finite.

    Strict means what vibsynth has always meant: ``true`` is not a number, ``1.5`` is not an
    integer, ``"3"`` is not a number (an integer is a valid float).
    """

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True, validate_default=True)


class Section(SettingsModel):
    """A section of the config file: its keys merge one by one across layers (a leaf is replaced whole)."""


class ValueModel(SettingsModel):
    """A structured value inside one key (a MIDI binding, a layout position): optional keys left out
    are dumped as absent, not ``null``, so ``model_dump()`` gives back what a file would hold."""

    @model_serializer(mode="wrap")
    def _without_nulls(self, handler: SerializerFunctionWrapHandler) -> Any:
        data = handler(self)
        return {k: v for k, v in data.items() if v is not None} if isinstance(data, dict) else data


def setting(
    default: Any,
    help: str,
    *,
    unit: str = "",
    allowed: str = "",
    schema: JsonSchema | None = None,
    **constraints: Any,
) -> Any:
    """Declare one setting (a pydantic ``Field``): default, one-line help, unit and constraints.

    Parameters
    ----------
    default : Any
        The default (``...`` for a required key).
    help : str
        One line: what the setting does (the ``description`` of the JSON Schema).
    unit : str
        Shown after ranges (``Hz``, ``ms``, ``(knob units)``); ``x-unit`` in the JSON Schema.
    allowed : str
        What is allowed, in words, when the constraints say it badly (structured values);
        ``x-allowed`` in the JSON Schema.
    schema : dict, optional
        Further JSON Schema keywords (e.g. ``propertyNames`` of a mapping with integer keys).
    **constraints
        Pydantic constraints: ``ge``, ``le``, ``gt``, ``lt``, ``pattern``, ``max_length``...
    """
    extra: JsonSchema = dict(schema or {})
    if unit:
        extra["x-unit"] = unit
    if allowed:
        extra["x-allowed"] = allowed
    return Field(default, description=help, json_schema_extra=extra or None, **constraints)


def problem(message: str, *path: str | int) -> PydanticCustomError:
    """The error a custom validator raises: ``message`` is shown as is, ``path`` points inside the value."""
    return PydanticCustomError(PROBLEM, "{message}", {"message": message, "path": tuple(path)})


def cross_problem(message: str, *keys: str) -> PydanticCustomError:
    """The error of a rule between keys (dotted, most likely culprit first); the message is complete."""
    return PydanticCustomError(CROSS_PROBLEM, "{message}", {"message": message, "keys": tuple(keys)})


# --------------------------------------------------------------------------- values in messages
def is_number(value: object) -> bool:
    """An int or float, not a bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_int(value: object) -> bool:
    """An int, not a bool."""
    return isinstance(value, int) and not isinstance(value, bool)


def fmt_number(value: float) -> str:
    """A bound as people write it: integers in full (``4294967295``), others like ``%g``."""
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:g}"


def show(value: Any) -> str:
    """A value in an error message, in YAML spelling (``true``, ``null``), shortened when long."""
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "null"}[value]
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return repr(value)
    return short_repr(value)


# --------------------------------------------------------------------------- schema -> words
def resolve(schema: JsonSchema, defs: JsonSchema) -> JsonSchema:
    """``schema`` with a ``$ref`` to ``#/$defs/...`` replaced by the definition (sibling keywords kept)."""
    ref = schema.get("$ref")
    if isinstance(ref, str) and ref.startswith("#/$defs/"):
        merged = dict(defs[ref.rsplit("/", 1)[1]])
        merged.update({k: v for k, v in schema.items() if k != "$ref"})
        return merged
    return schema


def alternatives(schema: JsonSchema) -> list[JsonSchema]:
    """The alternatives of a schema (``anyOf``/``oneOf``, nested ones flattened), or the schema itself."""
    options = schema.get("anyOf") or schema.get("oneOf")
    if not options:
        return [schema]
    return [inner for option in options for inner in alternatives(option)]


def _branches(schema: JsonSchema) -> tuple[list[JsonSchema], bool]:
    """Non-null alternatives of a schema and whether null is allowed."""
    options = alternatives(schema)
    if len(options) == 1 and options[0] is schema:
        return [schema], False
    return [o for o in options if o.get("type") != "null"], any(o.get("type") == "null" for o in options)


def _range(schema: JsonSchema, unit: str) -> str:
    low, high = (
        schema.get("exclusiveMinimum", schema.get("minimum")),
        schema.get("exclusiveMaximum", schema.get("maximum")),
    )
    lo = "(" if "exclusiveMinimum" in schema else "["
    hi = ")" if "exclusiveMaximum" in schema else "]"
    text = f"{lo}{'-inf' if low is None else fmt_number(low)}, {'inf' if high is None else fmt_number(high)}{hi}"
    return text + (f" {unit}" if unit else "")


def describe(schema: JsonSchema, defs: JsonSchema | None = None, *, unit: str | None = None) -> str:
    """What a schema allows, in words: ``an integer in [1, 64]``, ``one of gate, continuous``...

    ``x-allowed`` (from :func:`setting`) wins; ``x-unit`` follows the range.
    """
    defs = defs or {}
    schema = resolve(schema, defs)
    unit = schema.get("x-unit", "") if unit is None else unit
    if "x-allowed" in schema:
        return str(schema["x-allowed"])
    options, nullable = _branches(schema)
    if len(options) > 1 or nullable:
        text = " or ".join(describe(o, defs, unit=unit) for o in options)
        return text + (" or null" if nullable else "") if text else "null"
    enum = schema.get("enum", [schema["const"]] if "const" in schema else None)
    if enum is not None:
        return "one of " + ", ".join(dict.fromkeys("null" if v is None else str(v) for v in enum))
    kind = schema.get("type")
    if kind in ("integer", "number"):
        return f"{'an integer' if kind == 'integer' else 'a number'} in {_range(schema, unit)}"
    return {
        "boolean": "true or false",
        "string": "a string",
        "array": "a list",
        "object": "a mapping",
        "null": "null",
    }.get(str(kind), "a value")


def explain(schema: JsonSchema, value: Any, defs: JsonSchema | None = None, *, unit: str | None = None) -> str | None:
    """Why ``value`` breaks ``schema`` (a phrase: ``must be an integer``), or None when it seems fine.

    Only the value's own level is checked (items of a list are not walked).
    """
    defs = defs or {}
    schema = resolve(schema, defs)
    unit = schema.get("x-unit", "") if unit is None else unit
    options, nullable = _branches(schema)
    if "x-allowed" in schema:  # the field's own words apply to its alternatives too
        options = [{**o, "x-allowed": schema["x-allowed"]} for o in options]
    if value is None:
        allows_null = nullable or schema.get("type") == "null" or None in schema.get("enum", [])
        return None if allows_null else "must not be null"
    if len(options) > 1:
        reasons = [explain(o, value, defs, unit=unit) for o in options]
        if any(r is None for r in reasons):
            return None
        outside = [r for r in reasons if r and r.startswith("outside")]
        return outside[0] if outside else "not an allowed value"
    one = options[0]
    if nullable:
        return explain(one, value, defs, unit=unit)
    return _explain_one(one, value, defs, unit)


def _explain_one(schema: JsonSchema, value: Any, defs: JsonSchema, unit: str) -> str | None:
    enum = schema.get("enum", [schema["const"]] if "const" in schema else None)
    if enum is not None:
        return None if value in enum and not isinstance(value, bool) else "not an allowed value"
    kind = schema.get("type")
    if kind in ("integer", "number"):
        what = "an integer" if kind == "integer" else "a number"
        if not is_number(value):
            return f"must be {what}"
        if not math.isfinite(float(value)):
            return "must be finite"
        if kind == "integer" and not isinstance(value, int):
            return f"must be {what}"
        v = float(value)
        if (
            ("minimum" in schema and v < schema["minimum"])
            or ("exclusiveMinimum" in schema and v <= schema["exclusiveMinimum"])
            or ("maximum" in schema and v > schema["maximum"])
            or ("exclusiveMaximum" in schema and v >= schema["exclusiveMaximum"])
        ):
            return f"outside the allowed range {_range(schema, unit)}"
        return None
    if kind == "boolean":
        return None if isinstance(value, bool) else "must be true or false"
    if kind == "string":
        if not isinstance(value, str):
            return f"must be {describe(schema, defs, unit=unit) if 'x-allowed' in schema else 'a string'}"
        if "maxLength" in schema and len(value) > schema["maxLength"]:
            return f"is {len(value)} characters long (allowed: at most {schema['maxLength']})"
        if ("minLength" in schema and len(value) < schema["minLength"]) or (
            "pattern" in schema and not re.search(schema["pattern"], value)
        ):
            return f"must be {describe(schema, defs, unit=unit)}"
        return None
    if kind == "array":
        if not isinstance(value, list):
            return "must be a list"
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            return f"has {len(value)} items (allowed: at most {schema['maxItems']})"
        if "minItems" in schema and len(value) < schema["minItems"]:
            return f"has {len(value)} items (allowed: at least {schema['minItems']})"
        return None
    if kind == "object":
        return None if isinstance(value, dict) else "must be a mapping"
    return None
