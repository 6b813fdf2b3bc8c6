"""The one strict JSON reader for outside files (AHAP, Meta ``.haptic``): bounded size, depth and
count, finite numbers only, no duplicate keys, and one clear error naming the file.

Python's :mod:`json` accepts ``NaN``, ``Infinity`` and ``1e999`` (which becomes ``inf``) and keeps
the last of two equal keys; none of that reaches vibsynth. The size cap is checked before the
file is read (:func:`vibsynth.formats.files.read_text`), the depth and the number of values
right after parsing, before anything looks at the data.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from vibsynth.errors import VibsynthError
from vibsynth.formats.files import read_text

#: Where a value is in a document: keys and list indices (``("Pattern", 3, "Event")``).
JsonPath = tuple[str | int, ...]

__all__ = [
    "MAX_JSON_DEPTH",
    "MAX_JSON_VALUES",
    "JsonPath",
    "JsonFields",
    "load_json",
    "parse_json",
    "json_path",
    "json_shape",
]

#: Deepest nesting accepted: AHAP and .haptic files nest 6 levels.
MAX_JSON_DEPTH = 32
#: Most values (numbers, strings, lists, mappings) in one document: a 4 MiB file of small
#: numbers holds about a million; the formats read here never need more than a few hundred thousand.
MAX_JSON_VALUES = 1_000_000
#: Integers beyond this are not times or levels: refused (and Python never builds a huge int).
_MAX_INT_DIGITS = 18


class _Refused(Exception):
    """Internal: a rule of this reader is broken (turned into the caller's error)."""


def _constant(name: str) -> Any:
    raise _Refused(f"{name} is not a number vibsynth accepts (only finite numbers)")


def _float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _Refused(f"{text} is too large (only finite numbers)")
    return value


def _int(text: str) -> int:
    if len(text.lstrip("-")) > _MAX_INT_DIGITS:
        raise _Refused(f"the integer {text[:20]}... is too large")
    return int(text)


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Refused(f"key {key!r} appears twice in one object; keep one")
        out[key] = value
    return out


def _walk(data: Any) -> Iterator[int]:
    """Depth of every value (iterative: a deep document cannot exhaust the stack)."""
    stack: list[tuple[Any, int]] = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        yield depth
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)


def parse_json(
    text: str,
    origin: str,
    *,
    error: type[VibsynthError],
    max_depth: int = MAX_JSON_DEPTH,
    max_values: int = MAX_JSON_VALUES,
) -> Any:
    """Parse JSON text strictly.

    Parameters
    ----------
    text : str
    origin : str
        File name for messages.
    error : exception class
        Raised with one line ``origin[:line:col]: problem``.
    max_depth, max_values : int
        Caps on nesting and on the number of values.

    Raises
    ------
    error
        Not JSON (with line and column: a truncated file says so), NaN/Infinity/overflowing
        numbers, duplicate keys, too deep, too many values.
    """
    try:
        data = json.loads(text, parse_constant=_constant, parse_float=_float, parse_int=_int, object_pairs_hook=_pairs)
    except _Refused as exc:
        raise error(f"{origin}: {exc}") from None
    except json.JSONDecodeError as exc:
        truncated = exc.pos >= len(text.rstrip()) or exc.msg.startswith("Unterminated string")
        hint = "; the file ends too early (truncated?)" if truncated else ""
        raise error(f"{origin}:{exc.lineno}:{exc.colno}: not valid JSON ({exc.msg}){hint}") from None
    except RecursionError:
        raise error(f"{origin}: nested more than {max_depth} levels deep") from None
    except ValueError as exc:  # e.g. Python's limit on integer digits
        raise error(f"{origin}: not valid JSON ({exc})") from None
    count = 0
    for depth in _walk(data):
        count += 1
        if depth > max_depth:
            raise error(f"{origin}: nested more than {max_depth} levels deep")
        if count > max_values:
            raise error(f"{origin}: more than {max_values:,} values; not a file vibsynth reads")
    return data


def load_json(
    path: str | os.PathLike[str],
    *,
    error: type[VibsynthError],
    what: str,
    max_bytes: int,
    max_depth: int = MAX_JSON_DEPTH,
    max_values: int = MAX_JSON_VALUES,
) -> Any:
    """Read a JSON file of at most ``max_bytes`` (refused before reading) and parse it with :func:`parse_json`."""
    p = Path(path).expanduser()
    text = read_text(p, error=error, max_bytes=max_bytes, what=what)
    return parse_json(text, str(p), error=error, max_depth=max_depth, max_values=max_values)


def json_path(parts: tuple[str | int, ...]) -> str:
    """``Pattern[3].Event.Time`` from ``("Pattern", 3, "Event", "Time")``."""
    out = ""
    for part in parts:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def json_shape(parts: JsonPath) -> str:
    """A JSON path without its indices (``Pattern[].Event.Foo``): one name for every item alike."""
    return "".join("[]" if isinstance(p, int) else (f".{p}" if i else p) for i, p in enumerate(parts))


class JsonFields:
    """Typed access to a parsed JSON document: errors name the file and the JSON path; unknown keys are collected.

    Parameters
    ----------
    origin : str
        File name for messages.
    keys : dict
        Known keys by shape: the path's key names without indices (``("Pattern", "Event")``).
    error : exception class

    Attributes
    ----------
    unknown : list of str
        Shapes of unknown keys met (``Pattern[].Event.Foo``), each once, in order met.
    """

    def __init__(self, origin: str, keys: dict[tuple[str, ...], set[str]], error: type[VibsynthError]) -> None:
        self.origin, self.keys, self.error = origin, keys, error
        self.unknown: list[str] = []

    def fail(self, path: JsonPath, message: str) -> VibsynthError:
        """The error to raise: ``origin: path = value: message``."""
        where = json_path(path)
        if not where:
            return self.error(f"{self.origin}: {message}")
        return self.error(f"{self.origin}: {where}{' ' if message.startswith('= ') else ': '}{message}")

    def mapping(self, value: Any, path: JsonPath) -> dict[str, Any]:
        """``value`` as an object (unknown keys noted)."""
        if not isinstance(value, dict):
            raise self.fail(path, f"must be an object, got {_kind(value)}")
        known = self.keys.get(tuple(p for p in path if isinstance(p, str)), set())
        for key in sorted(value.keys() - known):
            shape = json_shape(path + (key,))
            if shape not in self.unknown:
                self.unknown.append(shape)
        return value

    def items(self, value: Any, path: JsonPath) -> list[Any]:
        """``value`` as a list."""
        if not isinstance(value, list):
            raise self.fail(path, f"must be a list, got {_kind(value)}")
        return value

    def require(self, holder: dict[str, Any], key: str, path: JsonPath) -> Any:
        """``holder[key]``, or the error naming the missing key."""
        if key not in holder:
            raise self.fail(path, f"missing key {key!r}")
        return holder[key]

    def number(self, value: Any, path: JsonPath, low: float = -math.inf, high: float = math.inf) -> float:
        """``value`` as a float in ``[low, high]``."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(path, f"= {_short(value)}: must be a number")
        if not low <= value <= high:
            raise self.fail(path, f"= {value!r}: outside the allowed range [{low:g}, {high:g}]")
        return float(value)


def _kind(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false", type(None): "null"}.get(
        type(value), "a number"
    )


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."
