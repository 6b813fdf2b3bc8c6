"""YAML documents that remember the line of every key, so each error can say ``file:line``; and the
way settings files (presets, clips) are written back: hand-editable blocks, checked before writing."""

from __future__ import annotations

import os
import reprlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from vibsynth.errors import ConfigError

Path_ = tuple[str, ...]


@dataclass
class YamlDocument:
    """A parsed YAML document with the line of every key.

    Attributes
    ----------
    data : Any
        The constructed document (``None`` for an empty file).
    lines : dict of tuple of str to int
        1-based line of each mapping key / sequence item, by path (keys as strings,
        sequence indices as decimal strings).
    origin : str
        File name (or description) used in messages.
    """

    data: Any
    lines: dict[Path_, int]
    origin: str

    def line(self, path: Path_) -> int | None:
        """1-based line of the deepest known prefix of ``path`` (None if none is known)."""
        for n in range(len(path), 0, -1):
            line = self.lines.get(tuple(str(p) for p in path[:n]))
            if line is not None:
                return line
        return None

    def where(self, path: Path_) -> str:
        """``origin:line`` of the deepest known prefix of ``path`` (``origin`` alone if unknown)."""
        line = self.line(path)
        return self.origin if line is None else f"{self.origin}:{line}"


def _walk_lines(node: yaml.Node, path: Path_, lines: dict[Path_, int], origin: str) -> None:
    if isinstance(node, yaml.MappingNode):
        seen: dict[str, int] = {}
        for key_node, value_node in node.value:
            key = str(key_node.value)
            line = key_node.start_mark.line + 1
            if key in seen:
                raise ConfigError(
                    f"{origin}:{line}: key {'.'.join(path + (key,))!r} appears twice (first on line {seen[key]}); "
                    "keep one"
                )
            seen[key] = line
            lines[path + (key,)] = line
            _walk_lines(value_node, path + (key,), lines, origin)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            lines[path + (str(i),)] = item.start_mark.line + 1
            _walk_lines(item, path + (str(i),), lines, origin)


def _document(loaded: Any, error: type[Exception]) -> YamlDocument:
    lines: dict[Path_, int] = {}
    if loaded.node is not None:
        try:
            _walk_lines(loaded.node, (), lines, loaded.origin)
        except ConfigError as exc:
            raise error(str(exc)) from None
    return YamlDocument(loaded.data, lines, loaded.origin)


def parse_yaml(
    text: str, origin: str, *, error: type[Exception] = ConfigError, what: str = "a config file"
) -> YamlDocument:
    """Parse YAML text, keeping the line of every key; duplicate keys are errors.

    The text goes through :func:`vibsynth.formats.yamlio.load_yaml` (size cap, no aliases, bounded
    nesting), the one YAML loader of vibsynth.

    Parameters
    ----------
    text : str
    origin : str
        File name for messages.
    error : exception class
        Raised (with ``origin:line:`` in the message) on syntax errors, refused documents
        and duplicate keys.
    what : str
        What the text is, for messages ("a preset").

    Returns
    -------
    document : YamlDocument
    """
    from vibsynth.formats.yamlio import load_yaml  # io imports numpy; keep config light to import

    return _document(load_yaml(text=text, origin=origin, error=error, what=what), error)


def read_yaml_file(
    path: str | os.PathLike[str], *, error: type[Exception] = ConfigError, what: str = "a config file"
) -> YamlDocument:
    """Read and parse a YAML file (see :func:`parse_yaml`): at most :data:`vibsynth.formats.files.MAX_YAML_BYTES`,
    refused before reading when larger; missing/unreadable files raise ``error``."""
    from vibsynth.formats.yamlio import load_yaml

    return _document(load_yaml(Path(path).expanduser(), error=error, what=what), error)


def yaml_value(text: str, origin: str) -> Any:
    """A value written in YAML syntax (environment variable, ``--set``); text that is not
    valid YAML is the string itself. Aliases and oversized values are still refused."""
    from vibsynth.formats.yamlio import load_yaml

    try:
        return load_yaml(text=text, origin=origin, error=ConfigError, what="a setting", syntax_error=_NotYaml).data
    except _NotYaml:
        return text


class _NotYaml(ConfigError):
    """Internal: a setting that is not YAML syntax (read as a plain string)."""


_SHORT = reprlib.Repr()
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = 8
_SHORT.maxstring = _SHORT.maxother = 80
_SHORT.maxlevel = 4


def short_repr(value: Any) -> str:
    """``repr`` for error messages, bounded: a long list or text is cut with ``...`` (reprlib
    never builds the full text, so a large value cannot blow up a message)."""
    return _SHORT.repr(value)


# --------------------------------------------------------------------------- writing settings files
SUFFIX = ".yaml"


def file_stem(path: Path) -> str:
    """A settings file's name without ``.yaml`` (its preset or clip name)."""
    return path.name[: -len(SUFFIX)] if path.name.endswith(SUFFIX) else path.stem


def dump_block(data: Mapping[str, Any], indent: str = "") -> str:
    """Block-style mapping at the top levels, short lists and leaf mappings inline: easy to hand-edit."""
    from vibsynth.formats.yamlio import dump_yaml

    out = []
    for key, value in data.items():
        if isinstance(value, Mapping) and value:
            out.append(f"{indent}{key}:\n" + dump_block(value, indent + "  "))
            continue
        text = dump_yaml(
            {key: value}, sort_keys=False, width=100, default_flow_style=None if isinstance(value, list) else False
        )
        out.append("".join(indent + line if line.strip() else line for line in text.splitlines(keepends=True)))
    return "".join(out)


def write_checked(target: Path, text: str, parse: Callable[[str, str, str], Any], error: type[Exception]) -> Path:
    """Write a settings file atomically, after reading the text back (never write what cannot be read).

    Parameters
    ----------
    target : pathlib.Path
    text : str
    parse : callable
        ``parse(text, origin, name)``: raises ``error`` when the text is not a valid file of its kind.
    error : exception class
        Also raised (naming the file) when it cannot be written.
    """
    from vibsynth.formats.files import atomic_write

    parse(text, str(target), file_stem(target))
    try:
        atomic_write(target, text)
    except OSError as exc:
        raise error(f"{target}: cannot write ({exc.strerror})") from None
    return target
