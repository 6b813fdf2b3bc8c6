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
Files are read through :func:`vibsynth.io.load_yaml` (1 MiB cap, no YAML aliases) and
written through :func:`vibsynth.io.atomic_write`. :class:`PresetLibrary` merges shipped
presets (package data) with the user's folder (user wins), and :class:`PresetWatcher`
reloads it while the service runs, re-reading only files whose (mtime, size, inode)
changed, with bounded work per poll (see docs/presets.md, "Hot reload").
"""
from __future__ import annotations

import difflib
import errno
import logging
import math
import os
import re
import stat
import threading
import time
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from vibsynth.config import Config, YamlDocument, parse_yaml, read_yaml_file, short_repr
from vibsynth.errors import PresetError, VibsynthError
from vibsynth.io import MAX_YAML_BYTES, atomic_write, dump_yaml, size_limit_message

__all__ = [
    "SCHEMA_VERSION",
    "BALANCE_LIMIT",
    "GLIDE_MAX_MS",
    "Preset",
    "parse_preset",
    "load_preset",
    "save_preset",
    "preset_to_yaml",
    "migrate",
    "MIGRATIONS",
    "PresetLibrary",
    "PresetWatcher",
    "load_library",
    "shipped_presets_dir",
    "default_user_dir",
]

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


# --------------------------------------------------------------------------- migration
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
        raise PresetError(f"{origin}: version = {version}: written by a newer vibsynth (this one reads versions "
                          f"0..{SCHEMA_VERSION}); upgrade vibsynth")
    if version < 0:
        raise PresetError(f"{origin}: version = {version}: outside the allowed range 0..{SCHEMA_VERSION}")
    while version < SCHEMA_VERSION:
        data = MIGRATIONS[version](data)
        version = data["version"]
    return data


# --------------------------------------------------------------------------- validation
def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _show(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "null"}[value]
    return short_repr(value)


def _check_number(where: str, key: str, value: Any, low: float, high: float, *, integer: bool = False,
                  unit: str = "", nullable: bool = False) -> float | None:
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
        raise PresetError(f"{doc.where(())}: a preset must be a mapping of keys ({', '.join(_KEY_ORDER)}), "
                          f"got {_show(data)}")
    for key in data:
        if key not in _KEY_ORDER:
            near = difflib.get_close_matches(str(key), _KEY_ORDER, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise PresetError(f"{at(str(key))}: unknown key {key!r}{hint} (allowed: {', '.join(_KEY_ORDER)})")
    data = migrate(dict(data), origin=at("version") if "version" in data else origin)
    for key in _REQUIRED:
        if key not in data:
            allowed = "a number in [0, 1]" if key == "intensity" else f"a number in [{-BALANCE_LIMIT:g}, {BALANCE_LIMIT:g}]"
            raise PresetError(f"{origin}: missing key {key!r} (allowed: {allowed})")

    name = data.get("name", stem)
    if name is None:
        raise PresetError(f"{origin}: missing key 'name'")
    if not isinstance(name, str) or not re.fullmatch(NAME_PATTERN, name):
        raise PresetError(f"{at('name')}: name = {_show(name)}: must be 1-64 letters, digits, '.', '_' or '-', "
                          "starting with a letter or digit")
    if stem is not None and name != stem:
        raise PresetError(f"{at('name')}: name = {name!r} does not match the file name {stem}{SUFFIX} "
                          f"(rename the file or change the name)")

    description = data.get("description", "")
    if description is None:
        description = ""
    if not isinstance(description, str):
        raise PresetError(f"{at('description')}: description = {_show(description)}: must be text (a string)")
    if len(description) > MAX_DESCRIPTION:
        raise PresetError(f"{at('description')}: description is {len(description)} characters long "
                          f"(allowed: at most {MAX_DESCRIPTION})")

    intensity = _check_number(at("intensity"), "intensity", data["intensity"], 0.0, 1.0)
    balance = _check_number(at("balance"), "balance", data["balance"], -BALANCE_LIMIT, BALANCE_LIMIT,
                            unit="(knob units)")
    glide = _check_number(at("glide_ms"), "glide_ms", data.get("glide_ms"), 0.0, GLIDE_MAX_MS, unit="ms",
                          nullable=True)
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
            raise PresetError(f"{doc.where(('tags', str(i)))}: tags[{i}] = {_show(tag)}: must be 1-32 letters, "
                              "digits, spaces, '.', '_' or '-'")

    provenance = data.get("provenance") or {}
    if not isinstance(provenance, dict):
        raise PresetError(f"{at('provenance')}: provenance = {_show(provenance)}: must be a mapping "
                          "(e.g. recording: file.wav)")
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
    are refused (see :func:`vibsynth.io.load_yaml`).
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
        text = dump_yaml({key: value}, sort_keys=False, width=100,
                         default_flow_style=None if isinstance(value, list) else False)
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


# --------------------------------------------------------------------------- library
def shipped_presets_dir() -> Path:
    """Folder of the presets shipped as package data (``vibsynth/data/presets``)."""
    return Path(str(resources.files("vibsynth.data").joinpath("presets")))


def default_user_dir() -> Path:
    """Platform folder for user presets: ``presets/`` in the user data folder.

    Linux ``~/.local/share/vibsynth/presets`` (``$XDG_DATA_HOME``), macOS
    ``~/Library/Application Support/vibsynth/presets``, Windows
    ``%LOCALAPPDATA%\\vibsynth\\presets``.
    """
    import platformdirs

    return Path(platformdirs.user_data_dir("vibsynth", appauthor=False)) / "presets"


def _files(folder: Path | None) -> list[Path]:
    if folder is None or not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.name.endswith(SUFFIX) and not p.name.startswith(".")
                  and p.is_file())


#: (mtime_ns, size, inode) of a preset file: what the watcher compares. Nothing is read to
#: make it; a file is re-read only when its signature changes.
Signature = tuple[int, int, int]

#: At most this many preset files per folder are used (bounded work per poll).
MAX_FILES_PER_FOLDER = 1000
#: At most this many folder entries (any kind) are looked at per folder and poll.
MAX_ENTRIES_PER_FOLDER = 20_000
#: A watcher poll reads and parses at most this many files and bytes (at least one file);
#: the rest are read by the next polls.
POLL_READ_FILES = 50
POLL_READ_BYTES = MAX_PRESET_BYTES
#: A file read less than this after its modification time is read once more when this time
#: has passed: an in-place edit of the same size within the file system's timestamp
#: resolution (coarse kernel clock; 2 s on FAT) leaves (mtime, size, inode) unchanged.
RACY_NS = 2_000_000_000


@dataclass
class _FileState:
    origin: str
    folder: Path
    signature: Signature
    preset: Preset | None  # the version in use: the last good one
    error: str | None  # why the file's current content is not in use
    recheck_ns: int | None  # wall-clock time of the one re-read of a racy file


class PresetLibrary:
    """Shipped presets plus a user folder; a user preset overrides a shipped one of the same name.

    Parameters
    ----------
    shipped_dir : path-like or None
        Default: :func:`shipped_presets_dir`. None = no shipped presets (tests).
    user_dir : path-like or None
        User presets (need not exist yet).
    load : bool
        Read the folders now.

    Attributes
    ----------
    errors : dict of str to str
        File -> message of every file whose content is not in use after the last
        :meth:`reload` (syntax or schema error, over the size cap); a previously good
        version of it stays in use.

    Notes
    -----
    :meth:`reload` lists both folders and stats each ``*.yaml`` file (hidden files, such as
    the temporary files of atomic writes, are ignored); it reads a file only when its
    (mtime, size, inode) changed, and never a file over :data:`MAX_PRESET_BYTES`. Problems
    (a file too large, a broken file, a folder that cannot be listed) are logged once when
    they appear, not at every poll, and a folder that can be listed again is reported once.
    """

    def __init__(self, shipped_dir: str | os.PathLike[str] | None = None,
                 user_dir: str | os.PathLike[str] | None = None, *, load: bool = True) -> None:
        self.shipped_dir = Path(shipped_dir) if shipped_dir is not None else None
        self.user_dir = Path(user_dir).expanduser() if user_dir is not None else None
        self._lock = threading.RLock()  # guards the published state (short holds only)
        self._reload_lock = threading.Lock()  # one reload at a time (watcher, save_user)
        self._presets: dict[str, Preset] = {}
        self._states: dict[Path, _FileState] = {}
        self._reported: dict[str, str] = {}
        self._clock: Callable[[], int] = time.time_ns
        self.errors: dict[str, str] = {}
        if load:
            self.reload()

    # ----------------------------------------------------------------- reporting once
    def _report(self, key: str, state: str, level: int, message: str) -> None:
        """Log ``message`` when ``key`` enters ``state`` (not again while it stays there)."""
        if self._reported.get(key) != state:
            self._reported[key] = state
            log.log(level, "%s", message)

    def _resolve(self, key: str, message: str | None = None) -> None:
        """``key`` has no problem any more; log ``message`` if a problem had been reported."""
        if self._reported.pop(key, None) is not None and message:
            log.warning("%s", message)

    # ----------------------------------------------------------------- scanning
    def _scan(self, folder: Path) -> dict[Path, Signature] | None:
        """Signatures of a folder's preset files (stat only); None when it cannot be listed."""
        key = f"folder:{folder}"
        found: dict[Path, Signature] = {}
        entries = 0
        try:
            with os.scandir(folder) as handle:
                for entry in handle:
                    entries += 1
                    if entries > MAX_ENTRIES_PER_FOLDER:
                        self._report(f"entries:{folder}", "many", logging.WARNING,
                                     f"preset folder {folder}: more than {MAX_ENTRIES_PER_FOLDER} entries; only the "
                                     f"first {MAX_ENTRIES_PER_FOLDER} are looked at")
                        break
                    name = entry.name
                    if name.startswith(".") or not name.endswith(SUFFIX):
                        continue
                    path = Path(entry.path)
                    try:
                        info = entry.stat()  # follows a symbolic link to its file
                    except FileNotFoundError:  # vanished, or a dangling link: no file
                        continue
                    except OSError as exc:  # e.g. a symbolic link loop
                        self._report(f"stat:{path}", f"errno {exc.errno}", logging.WARNING,
                                     f"{path}: cannot read ({_why(exc)}); skipped")
                        continue
                    self._resolve(f"stat:{path}")
                    if not stat.S_ISREG(info.st_mode):
                        continue
                    found[path] = (info.st_mtime_ns, info.st_size, info.st_ino)
                    if len(found) >= MAX_FILES_PER_FOLDER:
                        self._report(f"files:{folder}", "many", logging.WARNING,
                                     f"preset folder {folder}: more than {MAX_FILES_PER_FOLDER} preset files; "
                                     f"only {MAX_FILES_PER_FOLDER} are used")
                        break
        except FileNotFoundError:  # no folder is no presets (the user folder need not exist)
            self._resolve(key, f"preset folder {folder}: gone; no presets from it")
            return {}
        except OSError as exc:  # permission denied, symbolic link loop, not a folder
            self._report(key, f"errno {exc.errno}", logging.WARNING,
                         f"preset folder {folder}: cannot list it ({_why(exc)}); keeping the presets read from "
                         "it before until it can be listed again")
            return None
        self._resolve(key, f"preset folder {folder}: can be listed again")
        if entries <= MAX_ENTRIES_PER_FOLDER:
            self._reported.pop(f"entries:{folder}", None)
        if len(found) < MAX_FILES_PER_FOLDER:
            self._reported.pop(f"files:{folder}", None)
        return found

    def snapshot(self) -> dict[str, Signature]:
        """Signature (mtime_ns, size, inode) of every preset file in both folders (nothing is read)."""
        out: dict[str, Signature] = {}
        with self._reload_lock:
            for folder in (self.shipped_dir, self.user_dir):
                if folder is not None:
                    out.update({str(p): s for p, s in (self._scan(folder) or {}).items()})
        return out

    # ----------------------------------------------------------------- loading
    def reload(self, *, read_files: int | None = None, read_bytes: int | None = None) -> dict[str, str]:
        """Bring the library up to date with both folders.

        Only files whose (mtime, size, inode) changed are read. A file that fails to load
        keeps its last good version (if any); its error is logged once and recorded in
        :attr:`errors`. A file over :data:`MAX_PRESET_BYTES` is never read.

        Parameters
        ----------
        read_files, read_bytes : int, optional
            Read at most this many files / bytes in this call (at least one file; the watcher
            passes :data:`POLL_READ_FILES` / :data:`POLL_READ_BYTES`). Files left over are read
            by the next calls. Default: no limit.

        Returns
        -------
        changes : dict of str to str
            Name -> ``"added"``, ``"changed"`` or ``"removed"`` for every effective change.
        """
        with self._reload_lock:
            old = self._states
            states: dict[Path, _FileState] = {}
            now = self._clock()
            n_read = bytes_read = 0
            for origin, folder in (("shipped", self.shipped_dir), ("user", self.user_dir)):
                if folder is None:
                    continue
                listing = self._scan(folder)
                if listing is None:  # cannot list it now: keep what it gave before
                    states.update((p, s) for p, s in old.items() if s.folder == folder)
                    continue
                for path in sorted(listing):
                    signature, previous = listing[path], old.get(path)
                    if previous is not None and previous.signature == signature and not (
                            previous.recheck_ns is not None and now >= previous.recheck_ns):
                        states[path] = previous
                        continue
                    last_good = previous.preset if previous is not None else None
                    keeping = "; keeping the last good version" if last_good is not None else ""
                    size = signature[1]
                    if size > MAX_PRESET_BYTES:
                        message = size_limit_message(path, size, MAX_PRESET_BYTES, WHAT)
                        self._report(f"file:{path}", "too large", logging.WARNING, f"{message}; skipped{keeping}")
                        states[path] = _FileState(origin, folder, signature, last_good, message, None)
                        continue
                    if n_read and ((read_files is not None and n_read >= read_files)
                                   or (read_bytes is not None and bytes_read + size > read_bytes)):
                        if previous is not None:  # its old signature stays: read by a later call
                            states[path] = previous
                        continue
                    n_read += 1
                    bytes_read += size
                    recheck = signature[0] + RACY_NS if now - signature[0] < RACY_NS else None
                    try:
                        preset = load_preset(path, origin=origin)
                    except PresetError as exc:
                        self._report(f"file:{path}", str(exc), logging.ERROR, f"{exc}{keeping}")
                        states[path] = _FileState(origin, folder, signature, last_good, str(exc), recheck)
                    else:
                        self._resolve(f"file:{path}")
                        states[path] = _FileState(origin, folder, signature, preset, None, recheck)
            for path in old.keys() - states.keys():  # gone: a new problem with it is news again
                self._resolve(f"file:{path}")
            if states.keys() == old.keys() and all(states[p] is old[p] for p in states):
                return {}
            return self._publish(states)

    def _publish(self, states: dict[Path, _FileState]) -> dict[str, str]:
        presets: dict[str, Preset] = {}
        ordered = sorted(states.items(), key=lambda item: (item[1].origin != "shipped", str(item[0])))
        for path, state in ordered:  # shipped first, then user: user wins
            preset = state.preset
            if preset is None:
                continue
            if preset.name in presets and presets[preset.name].origin == preset.origin:
                self._report(f"twice:{preset.name}", str(path), logging.WARNING,
                             f"{path}: preset {preset.name!r} defined twice; using {presets[preset.name].path}")
                continue
            presets[preset.name] = preset
        errors = {str(p): s.error for p, s in ordered if s.error is not None}
        with self._lock:
            previous = self._presets
            self._presets, self._states, self.errors = presets, states, errors
        changes: dict[str, str] = {}
        for name in previous.keys() | presets.keys():
            if name not in presets:
                changes[name] = "removed"
            elif name not in previous:
                changes[name] = "added"
            elif previous[name] != presets[name]:
                changes[name] = "changed"
        return dict(sorted(changes.items()))

    # ----------------------------------------------------------------- queries
    def names(self) -> list[str]:
        """Sorted preset names."""
        with self._lock:
            return sorted(self._presets)

    def presets(self) -> list[Preset]:
        """Every effective preset, sorted by name."""
        with self._lock:
            return [self._presets[n] for n in sorted(self._presets)]

    def __contains__(self, name: object) -> bool:
        with self._lock:
            return name in self._presets

    def __len__(self) -> int:
        with self._lock:
            return len(self._presets)

    def get(self, name: str) -> Preset:
        """A preset by name.

        Raises
        ------
        PresetError
            Unknown name; the message lists close names.
        """
        with self._lock:
            preset = self._presets.get(name)
            names = sorted(self._presets)
        if preset is not None:
            return preset
        lowered = {n.lower(): n for n in names}
        near = [lowered[name.lower()]] if name.lower() in lowered else []
        near += [n for n in difflib.get_close_matches(name, names, n=4, cutoff=0.5) if n not in near]
        hint = f"; did you mean {', '.join(near)}?" if near else ""
        where = ", ".join(str(d) for d in (self.shipped_dir, self.user_dir) if d is not None)
        raise PresetError(f"unknown preset {name!r}{hint} ({len(names)} presets in {where}; "
                          "`vibsynth preset list` shows them)")

    def program_map(self) -> dict[int, str]:
        """MIDI program -> preset name.

        Presets with a ``program`` field take it (on a clash the user preset, then the
        first name, wins); the others fill the free numbers in name order.
        """
        with self._lock:
            presets = [self._presets[n] for n in sorted(self._presets)]
        out: dict[int, str] = {}
        explicit = sorted((p for p in presets if p.program is not None), key=lambda p: (p.origin != "user", p.name))
        for p in explicit:
            if p.program in out:
                log.warning("program %d is claimed by %r and %r; using %r", p.program, out[p.program], p.name,
                            out[p.program])
                continue
            out[p.program] = p.name  # type: ignore[index]
        free = (n for n in range(128) if n not in out)
        for p in presets:
            if p.program is None:
                number = next(free, None)
                if number is None:
                    break
                out[number] = p.name
        return dict(sorted(out.items()))

    def by_program(self, program: int) -> Preset:
        """The preset for a MIDI program number 0..127 (see :meth:`program_map`)."""
        if isinstance(program, bool) or not isinstance(program, int) or not 0 <= program <= 127:
            raise PresetError(f"program {program!r} is outside the allowed range 0..127")
        name = self.program_map().get(program)
        if name is None:
            raise PresetError(f"no preset for program {program} ({len(self)} presets)")
        return self.get(name)

    def user_path(self, name: str) -> Path:
        """Where a user preset of this name is (or would be) stored."""
        if not re.fullmatch(NAME_PATTERN, name):
            raise PresetError(f"preset name {name!r}: must be 1-64 letters, digits, '.', '_' or '-', "
                              "starting with a letter or digit")
        if self.user_dir is None:
            raise PresetError("no user preset folder configured (presets.user_dir)")
        return self.user_dir / f"{name}{SUFFIX}"

    def save_user(self, preset: Preset, *, overwrite: bool = False) -> Path:
        """Write a preset into the user folder (atomically) and reload."""
        path = self.user_path(preset.name)
        if path.exists() and not overwrite:
            raise PresetError(f"{path}: exists already (use --force to replace it)")
        save_preset(preset, path)
        self.reload()
        return path


def load_library(config: Config | None = None) -> PresetLibrary:
    """The preset library for a config: shipped presets + ``presets.user_dir`` (or the platform folder)."""
    user_dir = None
    if config is not None:
        user_dir = config.section("presets").get("user_dir")
    return PresetLibrary(shipped_presets_dir(), Path(user_dir).expanduser() if user_dir else default_user_dir())


# --------------------------------------------------------------------------- hot reload
class PresetWatcher:
    """Poll a library's folders and reload on change (edits, additions, removals).

    Parameters
    ----------
    library : PresetLibrary
    on_change : callable
        ``on_change(name)`` for every added, changed or removed preset (called from the
        watcher thread; exceptions are logged, never stop the watcher). For a removed
        preset ``library.get(name)`` raises: keep what is playing.
    interval_s : float
        Polling period (0.25 s: changes are picked up well within a second).

    Notes
    -----
    Everything happens in the watcher's own thread, never in the audio callback. A poll
    lists the folders and stats the ``*.yaml`` files (at most :data:`MAX_FILES_PER_FOLDER`
    each); it reads only files whose (mtime, size, inode) changed, at most
    :data:`POLL_READ_FILES` files and :data:`POLL_READ_BYTES` bytes per poll, and never a
    file over :data:`MAX_PRESET_BYTES` (logged once). A 50 MB file in the folder costs one
    ``stat`` per poll.
    """

    def __init__(self, library: PresetLibrary, on_change: Callable[[str], None], interval_s: float = 0.25) -> None:
        if not (_is_number(interval_s) and 0 < interval_s <= 10):
            raise PresetError(f"watch interval {interval_s!r} s is outside the allowed range (0, 10] s")
        self.library = library
        self.on_change = on_change
        self.interval_s = float(interval_s)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def poll(self) -> dict[str, str]:
        """Check once; read what changed (bounded, see the class notes), notify. Returns the changes."""
        changes = self.library.reload(read_files=POLL_READ_FILES, read_bytes=POLL_READ_BYTES)
        for name, kind in changes.items():
            log.info("preset %r %s", name, kind)
            try:
                self.on_change(name)
            except VibsynthError as exc:  # e.g. a removed preset that was playing: keep what plays
                log.warning("preset %r %s: %s", name, kind, exc)
            except Exception:  # noqa: BLE001 - a callback bug must not stop hot reload
                log.exception("preset %r: on_change callback failed", name)
        return changes

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            try:
                self.poll()
            except Exception:  # noqa: BLE001 - keep watching whatever happens
                log.exception("preset watcher: unexpected error")

    def start(self) -> "PresetWatcher":
        """Start the polling thread (daemon); returns self."""
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="vibsynth-preset-watcher", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> "PresetWatcher":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _why(exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return "symbolic link loop"
    return exc.strerror or str(exc)


def iter_preset_files(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Preset files of a folder (sorted)."""
    return _files(Path(folder))
