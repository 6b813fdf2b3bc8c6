"""Presets: named textures (intensity, balance, glide) in hand-editable YAML files.

Schema (version 1; annotated example in ``docs/presets.md``)::

    version: 1                 # schema version (required when saving; absent = 0, migrated)
    name: brick                # = the file name without .yaml; letters, digits, . _ -
    description: Coarse ...    # free text (optional)
    intensity: 0.75            # knob 0..1
    balance: -0.87             # knob units, within +-BALANCE_LIMIT (live controls clamp tighter)
    glide_ms: 50               # glide when the preset is applied, 0..10000 ms, or null = the channel's
    program: 3                 # MIDI program 0..127 (optional)
    tags: [rough, hard]        # optional
    provenance: {...}          # optional mapping: where the numbers came from

Every error names the file, the line, the key, the value and the allowed range.
Files are read through :func:`vibsynth.formats.yamlio.load_yaml` (1 MiB cap, no YAML aliases) and
written through :func:`vibsynth.formats.files.atomic_write`. :class:`PresetLibrary` merges shipped
presets (package data) with the user's folder (user wins), and :class:`PresetWatcher`
reloads it while the service runs, re-reading only files whose (mtime, size, inode)
changed, with bounded work per poll (see docs/presets.md, "Hot reload").
"""

from __future__ import annotations

import difflib
import logging
import math
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from vibsynth.errors import PresetError
from vibsynth.formats.files import MAX_YAML_BYTES, atomic_write
from vibsynth.formats.yamlio import dump_yaml
from vibsynth.settings.yamldoc import YamlDocument, parse_yaml, read_yaml_file, short_repr

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1
#: Presets may hold balances beyond the database's +-1 (recordings outside it), up to this.
BALANCE_LIMIT = 4.0
GLIDE_MAX_MS = 10_000.0
NAME_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}"
TAG_PATTERN = r"[A-Za-z0-9][A-Za-z0-9 _.-]{0,31}"
MAX_TAGS = 16
MAX_DESCRIPTION = 4000
SUFFIX = ".yaml"
WHAT = "a preset"
#: Preset files over this size are never read (a preset is about 1.5 KB).
MAX_PRESET_BYTES = MAX_YAML_BYTES

_KEY_ORDER = ("version", "name", "description", "intensity", "balance", "glide_ms", "program", "tags", "provenance")
_REQUIRED = ("intensity", "balance")


@dataclass(frozen=True)
class Preset:
    """A named texture.

    Attributes
    ----------
    name : str
    intensity : float
        Knob 0..1.
    balance : float
        Knob units (0 = the basis' mean spectrum, +-1 = 98th/2nd percentile of the database).
    description : str
    glide_ms : float or None
        Glide used when the preset is applied; None = the channel's current glide.
    program : int or None
        MIDI program number 0..127.
    tags : tuple of str
    provenance : dict
        Free-form record of where the values came from.
    version : int
        Schema version (always :data:`SCHEMA_VERSION` once loaded).
    path : pathlib.Path or None
        File it was loaded from (not part of equality).
    origin : str
        ``"shipped"``, ``"user"`` or ``""`` (not part of equality).
    """

    name: str
    intensity: float
    balance: float
    description: str = ""
    glide_ms: float | None = None
    program: int | None = None
    tags: tuple[str, ...] = ()
    provenance: Mapping[str, Any] = field(default_factory=dict)
    version: int = SCHEMA_VERSION
    path: Path | None = field(default=None, compare=False)
    origin: str = field(default="", compare=False)

    def to_dict(self) -> dict[str, Any]:
        """Plain data in file order (optional fields left out when empty)."""
        out: dict[str, Any] = {"version": self.version, "name": self.name}
        if self.description:
            out["description"] = self.description
        out["intensity"] = float(self.intensity)
        out["balance"] = float(self.balance)
        if self.glide_ms is not None:
            out["glide_ms"] = float(self.glide_ms)
        if self.program is not None:
            out["program"] = int(self.program)
        if self.tags:
            out["tags"] = list(self.tags)
        if self.provenance:
            out["provenance"] = _plain(self.provenance)
        return out


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):  # numpy scalars
        return value.item()
    return value


def _migrate_0_to_1(data: dict[str, Any]) -> dict[str, Any]:
    """v0 = a file without ``version`` (hand-written before the field existed); same fields otherwise."""
    out = dict(data)
    out["version"] = 1
    return out


#: ``MIGRATIONS[n]`` turns a version-n mapping into a version-(n+1) mapping.
MIGRATIONS: dict[int, Callable[[dict[str, Any]], dict[str, Any]]] = {0: _migrate_0_to_1}


def migrate(data: dict[str, Any], *, origin: str = "preset") -> dict[str, Any]:
    """Bring a preset mapping to :data:`SCHEMA_VERSION` (a missing ``version`` means 0).

    Raises
    ------
    PresetError
        A version newer than this vibsynth reads, or not an integer.
    """
    version = data.get("version", 0)
    if isinstance(version, bool) or not isinstance(version, int):
        raise PresetError(f"{origin}: version = {version!r}: must be an integer (allowed: 0..{SCHEMA_VERSION})")
    if version > SCHEMA_VERSION:
        raise PresetError(
            f"{origin}: version = {version}: written by a newer vibsynth (this one reads versions "
            f"0..{SCHEMA_VERSION}); upgrade vibsynth"
        )
    if version < 0:
        raise PresetError(f"{origin}: version = {version}: outside the allowed range 0..{SCHEMA_VERSION}")
    while version < SCHEMA_VERSION:
        data = MIGRATIONS[version](data)
        version = data["version"]
    return data


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _show(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "null"}[value]
    return short_repr(value)


def _check_number(
    where: str,
    key: str,
    value: Any,
    low: float,
    high: float,
    *,
    integer: bool = False,
    unit: str = "",
    nullable: bool = False,
) -> float | None:
    rng = f"[{low:g}, {high:g}]" + (f" {unit}" if unit else "")
    allowed = ("an integer" if integer else "a number") + f" in {rng}" + (" or null" if nullable else "")
    if value is None and nullable:
        return None
    if not _is_number(value) or (integer and not float(value).is_integer()):
        raise PresetError(f"{where}: {key} = {_show(value)}: must be {allowed.split(' in ')[0]} (allowed: {allowed})")
    v = float(value)
    if not math.isfinite(v):
        raise PresetError(f"{where}: {key} = {_show(value)}: must be finite (allowed: {allowed})")
    if not low <= v <= high:
        raise PresetError(f"{where}: {key} = {_show(value)}: outside the allowed range {rng}")
    return v


def _validate(data: Any, doc: YamlDocument, stem: str | None) -> Preset:
    origin = doc.origin

    def at(key: str) -> str:
        return doc.where((key,))

    if not isinstance(data, dict):
        raise PresetError(
            f"{doc.where(())}: a preset must be a mapping of keys ({', '.join(_KEY_ORDER)}), got {_show(data)}"
        )
    for key in data:
        if key not in _KEY_ORDER:
            near = difflib.get_close_matches(str(key), _KEY_ORDER, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise PresetError(f"{at(str(key))}: unknown key {key!r}{hint} (allowed: {', '.join(_KEY_ORDER)})")
    data = migrate(dict(data), origin=at("version") if "version" in data else origin)
    for key in _REQUIRED:
        if key not in data:
            allowed = (
                "a number in [0, 1]" if key == "intensity" else f"a number in [{-BALANCE_LIMIT:g}, {BALANCE_LIMIT:g}]"
            )
            raise PresetError(f"{origin}: missing key {key!r} (allowed: {allowed})")

    name = data.get("name", stem)
    if name is None:
        raise PresetError(f"{origin}: missing key 'name'")
    if not isinstance(name, str) or not re.fullmatch(NAME_PATTERN, name):
        raise PresetError(
            f"{at('name')}: name = {_show(name)}: must be 1-64 letters, digits, '.', '_' or '-', "
            "starting with a letter or digit"
        )
    if stem is not None and name != stem:
        raise PresetError(
            f"{at('name')}: name = {name!r} does not match the file name {stem}{SUFFIX} "
            f"(rename the file or change the name)"
        )

    description = data.get("description", "")
    if description is None:
        description = ""
    if not isinstance(description, str):
        raise PresetError(f"{at('description')}: description = {_show(description)}: must be text (a string)")
    if len(description) > MAX_DESCRIPTION:
        raise PresetError(
            f"{at('description')}: description is {len(description)} characters long "
            f"(allowed: at most {MAX_DESCRIPTION})"
        )

    intensity = _check_number(at("intensity"), "intensity", data["intensity"], 0.0, 1.0)
    balance = _check_number(
        at("balance"), "balance", data["balance"], -BALANCE_LIMIT, BALANCE_LIMIT, unit="(knob units)"
    )
    glide = _check_number(at("glide_ms"), "glide_ms", data.get("glide_ms"), 0.0, GLIDE_MAX_MS, unit="ms", nullable=True)
    program = _check_number(at("program"), "program", data.get("program"), 0, 127, integer=True, nullable=True)

    tags = data.get("tags") or []
    if isinstance(tags, str):
        raise PresetError(f"{at('tags')}: tags = {tags!r}: must be a list, e.g. tags: [{tags}]")
    if not isinstance(tags, list):
        raise PresetError(f"{at('tags')}: tags = {_show(tags)}: must be a list of short words")
    if len(tags) > MAX_TAGS:
        raise PresetError(f"{at('tags')}: {len(tags)} tags (allowed: at most {MAX_TAGS})")
    for i, tag in enumerate(tags):
        if not isinstance(tag, str) or not re.fullmatch(TAG_PATTERN, tag):
            raise PresetError(
                f"{doc.where(('tags', str(i)))}: tags[{i}] = {_show(tag)}: must be 1-32 letters, "
                "digits, spaces, '.', '_' or '-'"
            )

    provenance = data.get("provenance") or {}
    if not isinstance(provenance, dict):
        raise PresetError(
            f"{at('provenance')}: provenance = {_show(provenance)}: must be a mapping (e.g. recording: file.wav)"
        )
    return Preset(
        name=name,
        intensity=float(intensity),  # type: ignore[arg-type]
        balance=float(balance),  # type: ignore[arg-type]
        description=description.strip(),
        glide_ms=glide,
        program=None if program is None else int(program),
        tags=tuple(tags),
        provenance=provenance,
        version=SCHEMA_VERSION,
    )


def parse_preset(text: str, origin: str = "<preset>", *, name: str | None = None) -> Preset:
    """Parse and validate preset YAML text.

    Parameters
    ----------
    text : str
    origin : str
        File name for messages.
    name : str, optional
        Expected name (the file stem); the ``name`` key may be omitted, and must match if given.

    Raises
    ------
    PresetError
        Syntax error, duplicate or unknown key, wrong type, out-of-range value, newer version.
    """
    return _from_document(parse_yaml(text, origin, error=PresetError, what=WHAT), name)


def _from_document(doc: YamlDocument, name: str | None) -> Preset:
    if doc.data is None:
        raise PresetError(f"{doc.origin}: the file is empty (a preset needs at least intensity and balance)")
    return _validate(doc.data, doc, name)


def load_preset(path: str | os.PathLike[str], *, origin: str = "") -> Preset:
    """Read and validate a preset file (its name is the file name without ``.yaml``).

    Files over :data:`MAX_PRESET_BYTES` are refused before they are read, and YAML aliases
    are refused (see :func:`vibsynth.formats.yamlio.load_yaml`).
    """
    p = Path(path)
    stem = p.name[: -len(SUFFIX)] if p.name.endswith(SUFFIX) else p.stem
    doc = read_yaml_file(p, error=PresetError, what=WHAT)
    return replace(_from_document(doc, stem), path=p, origin=origin)


_HEADER = "# vibsynth preset (schema: docs/presets.md). Edit freely; saved atomically.\n"


def preset_to_yaml(preset: Preset, *, header: str = _HEADER) -> str:
    """YAML text of a preset (keys in schema order)."""
    return header + _dump_block(preset.to_dict())


def _dump_block(data: Mapping[str, Any], indent: str = "") -> str:
    """Block-style mapping at the top levels, short lists and leaf mappings inline: easy to hand-edit."""
    out = []
    for key, value in data.items():
        if isinstance(value, Mapping) and value:
            out.append(f"{indent}{key}:\n" + _dump_block(value, indent + "  "))
            continue
        text = dump_yaml(
            {key: value}, sort_keys=False, width=100, default_flow_style=None if isinstance(value, list) else False
        )
        out.append("".join(indent + line if line.strip() else line for line in text.splitlines(keepends=True)))
    return "".join(out)


def save_preset(preset: Preset, path: str | os.PathLike[str] | None = None, *, header: str = _HEADER) -> Path:
    """Validate and write a preset atomically; returns the path.

    Parameters
    ----------
    preset : Preset
    path : path-like, optional
        Default: ``preset.path``. The file name must be ``<name>.yaml``.
    """
    target = Path(path) if path is not None else preset.path
    if target is None:
        raise PresetError(f"preset {preset.name!r}: no file to save to")
    text = preset_to_yaml(preset, header=header)
    stem = target.name[: -len(SUFFIX)] if target.name.endswith(SUFFIX) else target.stem
    parse_preset(text, str(target), name=stem)  # never write what we could not read back
    try:
        atomic_write(target, text)
    except OSError as exc:
        raise PresetError(f"{target}: cannot write ({exc.strerror})") from None
    return target
