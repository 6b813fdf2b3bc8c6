"""The preset library: shipped presets (package data) merged with the user's folder (user wins),
re-read with bounded work per poll (only files whose (mtime, size, inode) changed).
"""

from __future__ import annotations

import difflib
import errno
import logging
import os
import re
import stat
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from vibsynth.errors import PresetError
from vibsynth.formats.files import size_limit_message
from vibsynth.settings.config import Config
from vibsynth.settings.models_preset import NAME_RULE
from vibsynth.settings.presets import MAX_PRESET_BYTES, NAME_PATTERN, SUFFIX, WHAT, Preset, load_preset, save_preset

log = logging.getLogger(__name__)


class UnknownPresetError(PresetError):
    """No preset (valid or broken) has this name: for a name typed on a command line, a usage error."""


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
    return sorted(p for p in folder.iterdir() if p.name.endswith(SUFFIX) and not p.name.startswith(".") and p.is_file())


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

    def __init__(
        self,
        shipped_dir: str | os.PathLike[str] | None = None,
        user_dir: str | os.PathLike[str] | None = None,
        *,
        load: bool = True,
    ) -> None:
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
                        self._report(
                            f"entries:{folder}",
                            "many",
                            logging.WARNING,
                            f"preset folder {folder}: more than {MAX_ENTRIES_PER_FOLDER} entries; only the "
                            f"first {MAX_ENTRIES_PER_FOLDER} are looked at",
                        )
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
                        self._report(
                            f"stat:{path}",
                            f"errno {exc.errno}",
                            logging.WARNING,
                            f"{path}: cannot read ({_why(exc)}); skipped",
                        )
                        continue
                    self._resolve(f"stat:{path}")
                    if not stat.S_ISREG(info.st_mode):
                        continue
                    found[path] = (info.st_mtime_ns, info.st_size, info.st_ino)
                    if len(found) >= MAX_FILES_PER_FOLDER:
                        self._report(
                            f"files:{folder}",
                            "many",
                            logging.WARNING,
                            f"preset folder {folder}: more than {MAX_FILES_PER_FOLDER} preset files; "
                            f"only {MAX_FILES_PER_FOLDER} are used",
                        )
                        break
        except FileNotFoundError:  # no folder is no presets (the user folder need not exist)
            self._resolve(key, f"preset folder {folder}: gone; no presets from it")
            return {}
        except OSError as exc:  # permission denied, symbolic link loop, not a folder
            self._report(
                key,
                f"errno {exc.errno}",
                logging.WARNING,
                f"preset folder {folder}: cannot list it ({_why(exc)}); keeping the presets read from "
                "it before until it can be listed again",
            )
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
                    if (
                        previous is not None
                        and previous.signature == signature
                        and not (previous.recheck_ns is not None and now >= previous.recheck_ns)
                    ):
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
                    if n_read and (
                        (read_files is not None and n_read >= read_files)
                        or (read_bytes is not None and bytes_read + size > read_bytes)
                    ):
                        if previous is not None:  # its old signature stays: read by a later call
                            states[path] = previous
                        continue
                    n_read += 1
                    bytes_read += size
                    recheck = signature[0] + RACY_NS if now - signature[0] < RACY_NS else None
                    try:
                        preset = load_preset(path, origin=origin)
                    except PresetError as exc:
                        skipped = keeping or "; skipped until the file is fixed"
                        self._report(f"file:{path}", str(exc), logging.WARNING, f"{exc}{skipped}")
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
                self._report(
                    f"twice:{preset.name}",
                    str(path),
                    logging.WARNING,
                    f"{path}: preset {preset.name!r} defined twice; using {presets[preset.name].path}",
                )
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
        broken = [message for path, message in self.errors.items() if Path(path).stem == name]
        if broken:  # the preset's file exists but is invalid: say what is wrong with it
            raise PresetError(broken[0])
        lowered = {n.lower(): n for n in names}
        near = [lowered[name.lower()]] if name.lower() in lowered else []
        near += [n for n in difflib.get_close_matches(name, names, n=4, cutoff=0.5) if n not in near]
        hint = f"; did you mean {', '.join(near)}?" if near else ""
        with self._lock:
            user = sum(1 for p in self._presets.values() if p.origin == "user")
        where = f"{len(names) - user} shipped, {user} in {self.user_dir}" if self.user_dir else "all shipped"
        raise UnknownPresetError(
            f"unknown preset {name!r}{hint} ({len(names)} presets: {where}; `vibsynth preset list` shows them)"
        )

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
                log.warning(
                    "program %d is claimed by %r and %r; using %r", p.program, out[p.program], p.name, out[p.program]
                )
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
            raise PresetError(f"preset name {name!r}: must be {NAME_RULE}")
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


def _why(exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return "symbolic link loop"
    return exc.strerror or str(exc)


def iter_preset_files(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Preset files of a folder (sorted)."""
    return _files(Path(folder))
