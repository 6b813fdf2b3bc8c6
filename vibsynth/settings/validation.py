"""Validate plain data (a YAML document, layered settings) against a settings model, with vibsynth's errors.

Pydantic reports *where in the data* a value failed (``('audio', 'rate')``); this module turns
that into vibsynth's one-line errors naming the file and line (through a :class:`Locator`, e.g.
a :class:`~vibsynth.settings.yamldoc.YamlDocument`), the dotted key, the value and what is
allowed, with "did you mean" for unknown keys. It knows nothing about configs or presets: any
model built from :class:`~vibsynth.settings.fields.SettingsModel` (config, preset, actuator
profile, and later haptic clips) is validated the same way::

    spec = model_spec(PresetModel)
    model = validate(spec, doc.data, doc, PresetError)   # raises InvalidPresetError(.problems)

Every error keeps all problems found, structured (:class:`Problem`: key, value, message), in
``exc.problems``; its text is the first problem in file order.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel, ValidationError

from vibsynth.errors import ClipError, ConfigError, PresetError, VibsynthError
from vibsynth.settings.fields import (
    CROSS_PROBLEM,
    PROBLEM,
    JsonSchema,
    Section,
    alternatives,
    describe,
    explain,
    resolve,
    show,
)

__all__ = [
    "Problem",
    "Locator",
    "FixedLocator",
    "InvalidConfigError",
    "InvalidPresetError",
    "InvalidClipError",
    "Leaf",
    "ModelSpec",
    "model_spec",
    "validate",
    "problems_of",
    "raise_problems",
    "did_you_mean",
]

M = TypeVar("M", bound=BaseModel)
_MISSING: Any = object()


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a settings document, structured for forms (the studio) and as one line.

    Attributes
    ----------
    key : str
        Dotted key as shown (``audio.rate``, ``tags[1]``, ``layout.2.name``).
    message : str
        What is wrong and what is allowed (``outside the allowed range [0, 1]``).
    value : Any
        The offending value (None when a key is missing).
    where : str
        ``file:line``, ``environment variable VAR``, ``command line``... (may be empty).
    detail : str
        The whole sentence after ``where:`` (``audio.rate = 100: outside ...``).
    line : int or None
        Line in the file, when known (used to report the first problem first).
    """

    key: str
    message: str
    value: Any = None
    where: str = ""
    detail: str = ""
    line: int | None = field(default=None, compare=False)

    @property
    def text(self) -> str:
        """The one-line error: ``where: detail``."""
        return f"{self.where}: {self.detail}" if self.where else self.detail


class InvalidConfigError(ConfigError):
    """A config (or actuator profile) breaks the schema; ``problems`` lists every problem found."""

    def __init__(self, message: str, problems: Sequence[Problem] = ()) -> None:
        super().__init__(message)
        self.problems: list[Problem] = list(problems)


class InvalidPresetError(PresetError):
    """A preset breaks the schema; ``problems`` lists every problem found."""

    def __init__(self, message: str, problems: Sequence[Problem] = ()) -> None:
        super().__init__(message)
        self.problems: list[Problem] = list(problems)


class InvalidClipError(ClipError):
    """A haptic clip file breaks the schema; ``problems`` lists every problem found."""

    def __init__(self, message: str, problems: Sequence[Problem] = ()) -> None:
        super().__init__(message)
        self.problems: list[Problem] = list(problems)


_ERRORS: dict[type[Exception], type[InvalidConfigError] | type[InvalidPresetError] | type[InvalidClipError]] = {
    ConfigError: InvalidConfigError,
    PresetError: InvalidPresetError,
    ClipError: InvalidClipError,
}


class Locator(Protocol):
    """Where a path of the data came from (a :class:`~vibsynth.settings.yamldoc.YamlDocument` is one)."""

    def where(self, path: tuple[str, ...]) -> str: ...

    def line(self, path: tuple[str, ...]) -> int | None: ...


@dataclass(frozen=True)
class FixedLocator:
    """Every path comes from the same place (``command line``, ``environment variable VAR``)."""

    origin: str

    def where(self, path: tuple[str, ...]) -> str:
        return self.origin

    def line(self, path: tuple[str, ...]) -> int | None:
        return None


# --------------------------------------------------------------------------- the model's keys
@dataclass(frozen=True)
class Leaf:
    """One setting: a key whose value is replaced whole (a number, a list, a mapping like ``midi.nrpn``).

    Attributes
    ----------
    key : str
        Dotted key.
    schema : dict
        Its JSON Schema (``$ref`` resolved against ``ModelSpec.defs``).
    default : Any
        Default value (plain data); ``...`` when required.
    help : str
    """

    key: str
    schema: JsonSchema
    default: Any
    help: str

    @property
    def required(self) -> bool:
        return self.default is Ellipsis


@dataclass(frozen=True)
class ModelSpec:
    """A settings model's keys, for messages: leaves and sections by dotted key, in declaration order."""

    model: type[BaseModel]
    leaves: dict[str, Leaf]
    sections: dict[str, list[str]]  # "" (top) or a section -> its direct keys
    defs: JsonSchema

    @property
    def nested(self) -> bool:
        """Whether the model has sections (a config) or is flat (a preset, a profile)."""
        return len(self.sections) > 1

    def allowed(self, key: str, *, unit: bool = True) -> str:
        leaf = self.leaves[key]
        return describe(leaf.schema, self.defs, unit=None if unit else "")


@cache
def model_spec(model: type[BaseModel]) -> ModelSpec:
    """The keys of a settings model (cached): :class:`~vibsynth.settings.fields.Section` fields are sections."""
    schema = model.model_json_schema()
    defs: JsonSchema = schema.get("$defs", {})
    leaves: dict[str, Leaf] = {}
    sections: dict[str, list[str]] = {}

    def walk(cls: type[BaseModel], props: JsonSchema, prefix: str) -> None:
        keys = sections.setdefault(prefix.rstrip("."), [])
        for name, info in cls.model_fields.items():
            dotted = prefix + name
            keys.append(name)
            annotation = info.annotation
            if isinstance(annotation, type) and issubclass(annotation, Section):
                sub = defs[annotation.__name__]
                walk(annotation, sub.get("properties", {}), dotted + ".")
                continue
            prop = props.get(name, {})
            default = Ellipsis if info.is_required() else _plain(info.get_default(call_default_factory=True))
            leaves[dotted] = Leaf(dotted, prop, default, info.description or "")

    walk(model, schema.get("properties", {}), "")
    return ModelSpec(model, leaves, sections, defs)


def _plain(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_dump(mode="python", exclude_none=False)
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def did_you_mean(key: str, candidates: Sequence[str], *, n: int = 3, quote: bool = False) -> str:
    """``; did you mean a, b?`` (empty when nothing is close)."""
    near = difflib.get_close_matches(key, list(candidates), n=n, cutoff=0.6)
    if not near:
        return ""
    return "; did you mean " + ", ".join(repr(k) if quote else k for k in near) + "?"


# --------------------------------------------------------------------------- errors -> problems
def _first_leaf(value: Any, path: tuple[str, ...]) -> tuple[str, ...]:
    """An unknown key holding a mapping is named by its first leaf (``audioo.rate``), like the file reads."""
    while isinstance(value, dict) and value:
        key = next(iter(value))
        path, value = path + (str(key),), value[key]
    return path


def _sub_schema(schema: JsonSchema, part: str | int, value: Any, defs: JsonSchema) -> JsonSchema:
    """The schema of ``value[part]`` (through ``anyOf``: the alternative for the value's kind)."""
    schema = resolve(schema, defs)
    for option in alternatives(schema):
        option = resolve(option, defs)
        if isinstance(value, list) and option.get("type") == "array":
            prefix = option.get("prefixItems") or []
            if isinstance(part, int) and part < len(prefix):
                return dict(prefix[part])
            return dict(option.get("items") or {})
        if isinstance(value, dict) and option.get("type") == "object":
            props = option.get("properties", {})
            if str(part) in props:
                return dict(props[str(part)])
            extra = option.get("additionalProperties")
            return dict(extra) if isinstance(extra, dict) else {}
    return {}


def _walk(
    value: Any, schema: JsonSchema, inner: Sequence[Any], defs: JsonSchema
) -> tuple[Any, JsonSchema, list[str | int]]:
    """Follow the inner part of an error location through the value (skipping pydantic's union tags)."""
    real: list[str | int] = []
    for part in inner:
        if isinstance(value, list) and isinstance(part, int) and 0 <= part < len(value):
            schema, value = _sub_schema(schema, part, value, defs), value[part]
        elif isinstance(value, dict) and part in value:
            schema, value = _sub_schema(schema, part, value, defs), value[part]
        else:
            continue  # a union member's tag, "[key]", or past the end
        real.append(part)
    return value, schema, real


def _display(key: str, parts: Sequence[str | int], value: Any) -> str:
    out = key
    for part in parts:
        if isinstance(value, list) and isinstance(part, int):
            out += f"[{part}]"
            value = value[part] if part < len(value) else None
        else:
            out += f".{part}"
            value = value.get(part) if isinstance(value, dict) else None
    return out


def _get(data: Any, path: Sequence[str | int]) -> Any:
    for part in path:
        if isinstance(data, dict) and part in data:
            data = data[part]
        elif isinstance(data, dict) and str(part) in data:
            data = data[str(part)]
        elif isinstance(data, list) and isinstance(part, int) and 0 <= part < len(data):
            data = data[part]
        else:
            return _MISSING
    return data


def _unknown(spec: ModelSpec, parent: str, path: tuple[str, ...]) -> str:
    dotted = ".".join(path)
    if not spec.nested:
        name = path[-1]
        return (
            f"unknown key {name!r}{did_you_mean(name, spec.sections[''], n=1, quote=True)} "
            f"(allowed: {', '.join(spec.sections[''])})"
        )
    known = sorted(spec.sections.get(parent, []))
    return (
        f"unknown key {dotted!r}{did_you_mean(dotted, list(spec.leaves))} "
        f"(allowed {'in ' + parent if parent else 'sections'}: {', '.join(known)})"
    )


def problems_of(
    exc: ValidationError,
    spec: ModelSpec,
    data: Any,
    locate: Locator,
    *,
    blame: Callable[[Sequence[str]], tuple[str, Locator]] | None = None,
) -> list[Problem]:
    """The problems of a :class:`pydantic.ValidationError`, each with its place, in file order.

    Parameters
    ----------
    exc : ValidationError
    spec : ModelSpec
    data : Any
        The data that was validated (for the offending values).
    locate : Locator
        Where a path of ``data`` came from.
    blame : callable, optional
        For a rule between keys: ``blame(keys) -> (key, locator)`` picks the key to name
        (default: the first, located by ``locate``).
    """
    found: dict[str, Problem] = {}
    for error in exc.errors(include_url=False):
        problem = _one(error, spec, data, locate, blame)
        if problem is not None and problem.key not in found:
            found[problem.key] = problem
    big = 1 << 60
    return sorted(found.values(), key=lambda p: big if p.line is None else p.line)


def _one(
    error: Any,
    spec: ModelSpec,
    data: Any,
    locate: Locator,
    blame: Callable[[Sequence[str]], tuple[str, Locator]] | None,
) -> Problem | None:
    kind, loc, ctx = error["type"], tuple(error["loc"]), error.get("ctx") or {}
    if kind == CROSS_PROBLEM:
        keys = list(ctx.get("keys") or ["?"])
        key, where = blame(keys) if blame is not None else (keys[0], locate)
        path = tuple(key.split("."))
        return Problem(
            key,
            str(ctx["message"]),
            _get(data, path),
            where.where(path),
            str(ctx["message"]),
            where.line(path),
        )
    # split the location into the setting (sections, then a leaf) and the part inside its value
    parent, leaf_key, i = "", "", 0
    while i < len(loc):
        candidate = f"{parent}.{loc[i]}" if parent else str(loc[i])
        i += 1
        if candidate in spec.leaves:
            leaf_key = candidate
            break
        if candidate in spec.sections:
            parent = candidate
            continue
        if kind == "extra_forbidden":
            path = tuple(str(p) for p in loc[:i])
            path = _first_leaf(_get(data, path), path) if spec.nested else path
            return _problem(".".join(path), _unknown(spec, parent, path), error.get("input"), path, locate)
        return None
    if not leaf_key:  # the error is about a section (or the whole document) itself
        path = tuple(str(p) for p in loc)
        value = _get(data, path)
        name = ".".join(path) or "the file"
        return _problem(name, f"must be a mapping of keys, got {show(value)}", value, path, locate, plain=True)
    leaf = spec.leaves[leaf_key]
    key_path = tuple(leaf_key.split("."))
    if kind == "missing" and i == len(loc):
        message = f"missing key {loc[-1]!r} (allowed: {spec.allowed(leaf_key, unit=False)})"
        return _problem(leaf_key, message, None, key_path[:-1], locate, plain=True)
    value = _get(data, key_path)
    inner = list(loc[i:])
    if kind == "missing":  # a key missing inside a structured value (a layout position without y)
        _, _, real = _walk(value, leaf.schema, inner[:-1], spec.defs)
        shown = _display(leaf_key, real, value)
        path = key_path + tuple(str(p) for p in real)
        return _problem(shown, f"{shown}: missing key {str(inner[-1])!r}", None, path, locate, plain=True)
    if kind == PROBLEM:
        inner += list(ctx.get("path") or ())
    sub_value, sub_schema, real = _walk(value, leaf.schema, inner, spec.defs)
    shown = _display(leaf_key, real, value)
    path = key_path + tuple(str(p) for p in real)
    reason: str
    if kind == PROBLEM:
        reason = str(ctx["message"])
        allowed = "" if real else describe(leaf.schema, spec.defs)
    else:
        schema = sub_schema if real else leaf.schema
        if kind == "extra_forbidden" and real:  # a key inside a structured value (a layout position)
            holder = _get(value, real[:-1])
            known = list(holder.keys()) if isinstance(holder, dict) else []
            props = resolve(_walk(value, leaf.schema, real[:-1], spec.defs)[1], spec.defs).get("properties", {})
            allowed_keys = ", ".join(props) if props else ", ".join(str(k) for k in known)
            return _problem(shown, f"unknown key {shown!r} (allowed: {allowed_keys})", sub_value, path, locate)
        why = explain(schema, sub_value, spec.defs, unit=leaf.schema.get("x-unit") if not real else None)
        allowed = describe(schema, spec.defs)
        if why is None:  # pydantic's own words, e.g. for a rule the schema does not state
            why = str(error.get("msg", "")) or "not an allowed value"
            why = why[0].lower() + why[1:]
        reason = why
    if allowed and allowed not in reason and not reason.startswith("outside") and "(allowed:" not in reason:
        reason += f" (allowed: {allowed})"
    return Problem(
        shown,
        reason,
        sub_value,
        locate.where(path),
        f"{shown} = {show(sub_value)}: {reason}",
        locate.line(path),
    )


def _problem(
    key: str, message: str, value: Any, path: tuple[str, ...], locate: Locator, *, plain: bool = False
) -> Problem:
    detail = f"{key} {message}" if plain and message.startswith("must") else message
    return Problem(key, message, value, locate.where(path), detail, locate.line(path))


def raise_problems(problems: Sequence[Problem], error: type[Exception]) -> None:
    """Raise ``error``'s structured subclass (text: the first problem; ``.problems``: all)."""
    cls = _ERRORS.get(error)
    if cls is None:
        raise error(problems[0].text)
    raise cls(problems[0].text, problems) from None


def validate(
    spec: ModelSpec,
    data: Any,
    locate: Locator,
    error: type[VibsynthError],
    *,
    context: Mapping[str, Any] | None = None,
    blame: Callable[[Sequence[str]], tuple[str, Locator]] | None = None,
) -> Any:
    """Validate plain data against ``spec.model``; problems raise ``error`` (structured, see :func:`raise_problems`).

    Returns
    -------
    model : instance of ``spec.model``
    """
    try:
        return spec.model.model_validate(data, context=dict(context or {}))
    except ValidationError as exc:
        problems = problems_of(exc, spec, data, locate, blame=blame)
        if not problems:  # pragma: no cover - every pydantic error maps to a problem
            raise error(f"{locate.where(())}: {' '.join(str(exc).split())}") from None
        raise_problems(problems, error)
        raise  # pragma: no cover - raise_problems always raises
