"""The one YAML loader and dumper (config, presets, bases, actuator profiles, MIDI learn).

:func:`load_yaml` refuses a file over its size cap before reading it, refuses YAML aliases
(``*name``: a 381-byte "billion laughs" file expands to gigabytes) and nesting deeper than
:data:`~vibsynth.formats.files.MAX_YAML_DEPTH`, naming ``file:line``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from vibsynth.errors import InputError
from vibsynth.formats.files import MAX_YAML_BYTES, MAX_YAML_DEPTH, read_text, size_limit_message

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    pass


class _Refused(Exception):
    """Internal: the document breaks a rule of :func:`load_yaml` (turned into the caller's error)."""


class _GuardedComposer(Composer):
    """PyYAML's composer, refusing aliases and deep nesting as the events arrive.

    The parser produces events lazily, so a refused document is never parsed further, let
    alone expanded or constructed.
    """

    def _setup_guard(self, what: str, max_depth: int) -> None:
        self._what, self._max_depth, self._depth = what, max_depth, 0
        self._anchor_lines: dict[str, int] = {}

    def compose_node(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()  # type: ignore[attr-defined]  # from the parser mixed in beside us
        mark = event.start_mark
        if isinstance(event, yaml.AliasEvent):
            line = self._anchor_lines.get(event.anchor or "")
            where = f" (anchor '&{event.anchor}' on line {line})" if line else ""
            raise _Refused(
                f"{mark.line + 1}:{mark.column + 1}: YAML alias "
                f"'*{event.anchor}'{where}: aliases are not allowed in {self._what} (they can "
                "expand a small file into gigabytes); write the value out instead"
            )
        if self._depth >= self._max_depth:
            raise _Refused(
                f"{event.start_mark.line + 1}:{event.start_mark.column + 1}: nested more than "
                f"{self._max_depth} levels deep (not allowed in {self._what})"
            )
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            self._anchor_lines.setdefault(anchor, event.start_mark.line + 1)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


try:  # libyaml's parser when PyYAML was built with it (fast), else PyYAML's own
    from yaml.cyaml import CParser as _CParser  # type: ignore[attr-defined]

    class _GuardedLoader(_GuardedComposer, _CParser, SafeConstructor, Resolver):
        def __init__(self, text: str, what: str, max_depth: int) -> None:
            _CParser.__init__(self, text)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
            self._setup_guard(what, max_depth)

except ImportError:  # pragma: no cover - depends on how PyYAML was built
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _GuardedLoader(Reader, Scanner, Parser, _GuardedComposer, SafeConstructor, Resolver):  # type: ignore[no-redef]
        def __init__(self, text: str, what: str, max_depth: int) -> None:
            Reader.__init__(self, text)
            Scanner.__init__(self)
            Parser.__init__(self)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
            self._setup_guard(what, max_depth)


@dataclass(frozen=True)
class LoadedYaml:
    """A YAML document read by :func:`load_yaml`.

    Attributes
    ----------
    data : Any
        The document (``None`` for an empty one): plain dicts/lists/scalars, or ruamel.yaml's
        comment-keeping ``CommentedMap`` with ``round_trip=True``.
    node : yaml.Node or None
        PyYAML's node tree, for line numbers (``node.start_mark.line`` is 0-based).
    origin : str
        The file name (or description) used in messages.
    """

    data: Any
    node: yaml.Node | None
    origin: str


def load_yaml(
    path: str | os.PathLike[str] | None = None,
    *,
    text: str | None = None,
    origin: str | None = None,
    error: type[Exception] = InputError,
    what: str = "a YAML file",
    max_bytes: int = MAX_YAML_BYTES,
    round_trip: bool = False,
    syntax_error: type[Exception] | None = None,
) -> LoadedYaml:
    """Read YAML safely: the one loader for every YAML file or value vibsynth reads.

    The rules, in this order:

    1. a file over ``max_bytes`` is refused before a byte is read (text over it too);
    2. a YAML alias (``*name``) is refused: with aliases a 381-byte "billion laughs" file
       expands to gigabytes, and presets, configs, profiles and bases have no use for them;
    3. nesting deeper than :data:`MAX_YAML_DEPTH` is refused (no ``RecursionError``);
    4. only plain data is built (safe loader: no Python objects).

    Refusals and syntax errors name ``file:line:column``. A refused document is never
    expanded, constructed or printed.

    Parameters
    ----------
    path : path-like, optional
        The file to read; or give ``text``.
    text : str, optional
        YAML text (an environment variable, ``--set`` value, package data).
    origin : str, optional
        Name for messages (default: the path).
    error : exception type
        Raised for every problem (a :class:`~vibsynth.errors.VibsynthError` subclass).
    what : str
        What the file is, for messages ("a preset", "a config file").
    max_bytes : int
        Size cap (default :data:`MAX_YAML_BYTES`; bases use :data:`MAX_BASIS_BYTES`).
    round_trip : bool
        Return ruamel.yaml's comment-keeping document (MIDI learn edits the user's config
        in place) instead of plain data; the same checks run first.
    syntax_error : exception type, optional
        Raised instead of ``error`` for a plain YAML syntax error (lets a caller fall back to
        reading a value as a string); the refusals above always raise ``error``.

    Returns
    -------
    loaded : LoadedYaml
    """
    if (path is None) == (text is None):
        raise TypeError("load_yaml: give exactly one of path and text")
    if path is not None:
        p = Path(path).expanduser()
        origin = origin or str(p)
        text = read_text(p, error=error, max_bytes=max_bytes, what=what)
    else:
        origin = origin or "<text>"
        assert text is not None
        if len(text) > max_bytes or len(text.encode("utf-8", "surrogatepass")) > max_bytes:
            size = len(text.encode("utf-8", "surrogatepass"))
            raise error(size_limit_message(origin, size, max_bytes, what))
    loader = _GuardedLoader(text, what, MAX_YAML_DEPTH)
    try:
        node = loader.get_single_node()
        data = loader.construct_document(node) if node is not None and not round_trip else None
    except _Refused as exc:
        raise error(f"{origin}:{exc}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        place = f"{origin}:{mark.line + 1}:{mark.column + 1}" if mark else origin
        problem = " ".join(p for p in (exc.context, exc.problem) if p)
        raise (syntax_error or error)(f"{place}: YAML syntax error: {problem}") from None
    except yaml.YAMLError as exc:
        raise (syntax_error or error)(f"{origin}: YAML error: {' '.join(str(exc).split())}") from None
    except (ValueError, OverflowError) as exc:  # e.g. an integer of 5000 digits
        problem = " ".join(str(exc).split(";")[0].split())  # not Python's advice on set_int_max_str_digits
        raise error(f"{origin}: cannot read a value: {problem}") from None
    except RecursionError:  # pragma: no cover - the depth cap comes first
        raise error(f"{origin}: nested too deeply") from None
    finally:
        loader.dispose()
    if round_trip and node is not None:
        data = _round_trip_load(text, origin, error)
    return LoadedYaml(data, node, origin)


def _round_trip_load(text: str, origin: str, error: type[Exception]) -> Any:
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError as RuamelError

    loader = YAML(typ="rt")
    loader.preserve_quotes = True
    try:
        return loader.load(text)
    except RuamelError as exc:  # e.g. a key twice (PyYAML keeps the last one)
        mark = getattr(exc, "problem_mark", None)
        place = f"{origin}:{mark.line + 1}" if mark is not None else origin
        problem = " ".join(p for p in (getattr(exc, "context", None), getattr(exc, "problem", None)) if p)
        raise error(f"{place}: YAML error: {problem or ' '.join(str(exc).split())}") from None


class _NoAliasDumper(yaml.SafeDumper):
    """Writes shared values out in full: vibsynth never writes an alias it would refuse to read."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def dump_yaml(data: Any, **options: Any) -> str:
    """YAML text of plain data, without anchors/aliases (see :func:`load_yaml`).

    ``options`` go to :func:`yaml.dump` (``sort_keys``, ``width``, ``default_flow_style``...).
    """
    options.setdefault("allow_unicode", True)
    return str(yaml.dump(data, Dumper=_NoAliasDumper, **options))
