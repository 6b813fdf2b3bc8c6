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

import logging
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from vibsynth.errors import PresetError
from vibsynth.formats.files import MAX_YAML_BYTES
from vibsynth.settings.fields import show
from vibsynth.settings.models_preset import (
    BALANCE_LIMIT,
    GLIDE_MAX_MS,
    MAX_DESCRIPTION,
    MAX_TAGS,
    NAME_PATTERN,
    PRESET_VERSION,
    TAG_PATTERN,
    PresetModel,
)
from vibsynth.settings.validation import InvalidPresetError, model_spec, validate
from vibsynth.settings.yamldoc import (
    SUFFIX,
    YamlDocument,
    dump_block,
    file_stem,
    parse_yaml,
    read_yaml_file,
    write_checked,
)

__all__ = [
    "BALANCE_LIMIT",
    "GLIDE_MAX_MS",
    "MAX_DESCRIPTION",
    "MAX_PRESET_BYTES",
    "MAX_TAGS",
    "MIGRATIONS",
    "NAME_PATTERN",
    "SCHEMA_VERSION",
    "SUFFIX",
    "TAG_PATTERN",
    "WHAT",
    "Preset",
    "load_preset",
    "migrate",
    "parse_preset",
    "preset_from_data",
    "preset_to_yaml",
    "save_preset",
]

log = logging.getLogger(__name__)

SCHEMA_VERSION = PRESET_VERSION
WHAT = "a preset"
#: Preset files over this size are never read (a preset is about 1.5 KB).
MAX_PRESET_BYTES = MAX_YAML_BYTES


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


def _validate(data: Any, doc: YamlDocument, stem: str | None) -> Preset:
    """Check a preset document against :class:`~vibsynth.settings.models_preset.PresetModel` (after migration)."""
    origin = doc.origin
    spec = model_spec(PresetModel)
    if not isinstance(data, dict):
        raise PresetError(
            f"{doc.where(())}: a preset must be a mapping of keys ({', '.join(spec.sections[''])}), got {show(data)}"
        )
    try:  # an unknown key is reported before anything about the version (it may be a misspelt one)
        validate(spec, {k: v for k, v in data.items() if k != "version"}, doc, PresetError)
    except InvalidPresetError as exc:
        if any(p.message.startswith("unknown key") for p in exc.problems):
            raise
    data = migrate(dict(data), origin=doc.where(("version",)) if "version" in data else origin)
    model: PresetModel = validate(spec, data, doc, PresetError)
    name = model.name if model.name is not None else stem
    if name is None:
        raise PresetError(f"{origin}: missing key 'name'")
    if stem is not None and name != stem:
        raise PresetError(
            f"{doc.where(('name',))}: name = {name!r} does not match the file name {stem}{SUFFIX} "
            f"(rename the file or change the name)"
        )
    return Preset(
        name=name,
        intensity=float(model.intensity),
        balance=float(model.balance),
        description=(model.description or "").strip(),
        glide_ms=None if model.glide_ms is None else float(model.glide_ms),
        program=model.program,
        tags=tuple(model.tags or ()),
        provenance=data.get("provenance") or {},
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


def preset_from_data(data: Any, origin: str, *, name: str | None = None) -> Preset:
    """Validate plain data (a form, a request body) exactly as a preset file's content is validated.

    Parameters
    ----------
    data : Any
        What a preset file would hold (a mapping of preset keys).
    origin : str
        Named in messages instead of ``file:line``.
    name : str, optional
        Expected name (the ``name`` key may be omitted, and must match if given).

    Raises
    ------
    InvalidPresetError
        ``.problems`` lists every problem, each with its key (for errors beside form fields).
    PresetError
        Not a mapping, a newer version, a missing name.
    """
    return _validate(data, YamlDocument(data, {}, origin), name)


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
    doc = read_yaml_file(p, error=PresetError, what=WHAT)
    return replace(_from_document(doc, file_stem(p)), path=p, origin=origin)


_HEADER = "# vibsynth preset (schema: docs/presets.md). Edit freely; saved atomically.\n"


def preset_to_yaml(preset: Preset, *, header: str = _HEADER) -> str:
    """YAML text of a preset (keys in schema order)."""
    return header + dump_block(preset.to_dict())


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
    return write_checked(target, preset_to_yaml(preset, header=header), _parse_named, PresetError)


def _parse_named(text: str, origin: str, name: str) -> Preset:
    return parse_preset(text, origin, name=name)
