"""Libraries of named settings files (presets, haptic clips): shipped files (package data) merged
with the user's folder (user wins), re-read with bounded work per poll (only files whose
(mtime, size, inode) changed).

:class:`FileLibrary` does the folder work for any kind of file described by a :class:`LibraryKind`;
:class:`PresetLibrary` adds what only presets have (MIDI program numbers), and
:class:`vibsynth.settings.clips.ClipLibrary` is the clips' library.
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
from typing import Generic, Protocol, TypeVar

from vibsynth.errors import PresetError, VibsynthError
from vibsynth.formats.files import size_limit_message
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.models_preset import NAME_RULE
from vibsynth.settings.presets import MAX_PRESET_BYTES, NAME_PATTERN, SUFFIX, WHAT, Preset, load_preset, save_preset

log = logging.getLogger(__name__)


class UnknownPresetError(PresetError):
    """No preset (valid or broken) has this name: for a name typed on a command line, a usage error."""


def shipped_dir(folder: str = "presets") -> Path:
    """Folder of the files of a kind shipped as package data (``vibsynth/data/<folder>``)."""
    return Path(str(resources.files("vibsynth.data").joinpath(folder)))


def shipped_presets_dir() -> Path:
    """Folder of the presets shipped as package data (``vibsynth/data/presets``)."""
    return shipped_dir("presets")


def default_user_dir(folder: str = "presets") -> Path:
    """Platform folder for user files of a kind: ``<folder>/`` in the user data folder.

    For presets: Linux ``~/.local/share/vibsynth/presets`` (``$XDG_DATA_HOME``), macOS
    ``~/Library/Application Support/vibsynth/presets``, Windows
    ``%LOCALAPPDATA%\\vibsynth\\presets``.
    """
    import platformdirs

    return Path(platformdirs.user_data_dir("vibsynth", appauthor=False)) / folder


class LibraryItem(Protocol):
    """What a library holds: a named, loaded file (a preset, a clip)."""

    @property
    def name(self) -> str: ...

    @property
    def origin(self) -> str: ...

    @property
    def path(self) -> Path | None: ...


T = TypeVar("T", bound=LibraryItem)


@dataclass(frozen=True)
class LibraryKind(Generic[T]):
    """A kind of named settings file, for :class:`FileLibrary`.

    Attributes
    ----------
    noun : str
        ``"preset"``, ``"clip"``: used in every message (``unknown clip 'x'``).
    what : str
        ``"a preset"``: for size messages.
    folder : str
        Package data folder of the shipped files and name of the user folder (``presets``).
    section : str
        Config section holding ``user_dir`` (``presets``, ``clips``).
    load : callable
        ``load(path, origin=...) -> item``; raises ``error``.
    save : callable
        ``save(item, path) -> Path``.
    error, unknown : exception classes
        What a broken file raises; what :meth:`FileLibrary.get` raises for an unknown name.
    max_bytes : int
        Files over this size are never read.
    suffix : str
    """

    noun: str
    what: str
    folder: str
    section: str
    load: Callable[..., T]
    save: Callable[[T, Path], Path]
    error: type[VibsynthError]
    unknown: type[VibsynthError]
    max_bytes: int
    suffix: str = SUFFIX


def _files(folder: Path | None, suffix: str = SUFFIX) -> list[Path]:
    if folder is None or not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.name.endswith(suffix) and not p.name.startswith(".") and p.is_file())


#: (mtime_ns, size, inode) of a file: what the watcher compares. Nothing is read to
#: make it; a file is re-read only when its signature changes.
Signature = tuple[int, int, int]

#: At most this many files per folder are used (bounded work per poll).
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
class _FileState(Generic[T]):
    origin: str
    folder: Path
    signature: Signature
    item: T | None  # the version in use: the last good one
    error: str | None  # why the file's current content is not in use
    recheck_ns: int | None  # wall-clock time of the one re-read of a racy file


class FileLibrary(Generic[T]):
    """Shipped files plus a user folder; a user file overrides a shipped one of the same name.

    A subclass sets :attr:`kind` (:class:`PresetLibrary`, :class:`vibsynth.settings.clips.ClipLibrary`).

    Parameters
    ----------
    shipped_dir : path-like or None
        Shipped files. None = none (tests).
    user_dir : path-like or None
        User files (need not exist yet).
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
    (mtime, size, inode) changed, and never a file over ``kind.max_bytes``. Problems
    (a file too large, a broken file, a folder that cannot be listed) are logged once when
    they appear, not at every poll, and a folder that can be listed again is reported once.
    """

    #: What the files are (presets, clips) and how to read them: set by each subclass.
    kind: LibraryKind[T]

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
        self._items: dict[str, T] = {}
        self._states: dict[Path, _FileState[T]] = {}
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
        """Signatures of a folder's files (stat only); None when it cannot be listed."""
        noun, suffix = self.kind.noun, self.kind.suffix
        key = f"folder:{folder}"
        found: dict[Path, Signature] = {}
        entries = 0
        too_many = False
        try:
            with os.scandir(folder) as handle:
                for entry in handle:
                    entries += 1
                    if entries > MAX_ENTRIES_PER_FOLDER:
                        self._report(
                            f"entries:{folder}",
                            "many",
                            logging.WARNING,
                            f"{noun} folder {folder}: more than {MAX_ENTRIES_PER_FOLDER} entries; only the "
                            f"first {MAX_ENTRIES_PER_FOLDER} are looked at",
                        )
                        break
                    name = entry.name
                    if name.startswith(".") or not name.endswith(suffix):
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
                    if len(found) >= MAX_FILES_PER_FOLDER:  # one more than the cap: say so, use the cap
                        self._report(
                            f"files:{folder}",
                            "many",
                            logging.WARNING,
                            f"{noun} folder {folder}: more than {MAX_FILES_PER_FOLDER} {noun} files; "
                            f"only {MAX_FILES_PER_FOLDER} are used",
                        )
                        too_many = True
                        break
                    found[path] = (info.st_mtime_ns, info.st_size, info.st_ino)
        except FileNotFoundError:  # no folder is no files (the user folder need not exist)
            self._resolve(key, f"{noun} folder {folder}: gone; no {noun}s from it")
            return {}
        except OSError as exc:  # permission denied, symbolic link loop, not a folder
            self._report(
                key,
                f"errno {exc.errno}",
                logging.WARNING,
                f"{noun} folder {folder}: cannot list it ({_why(exc)}); keeping the {noun}s read from "
                "it before until it can be listed again",
            )
            return None
        self._resolve(key, f"{noun} folder {folder}: can be listed again")
        if entries <= MAX_ENTRIES_PER_FOLDER:
            self._reported.pop(f"entries:{folder}", None)
        if not too_many:
            self._reported.pop(f"files:{folder}", None)
        return found

    def snapshot(self) -> dict[str, Signature]:
        """Signature (mtime_ns, size, inode) of every file in both folders (nothing is read)."""
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
        :attr:`errors`. A file over ``kind.max_bytes`` is never read.

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
        kind = self.kind
        with self._reload_lock:
            old = self._states
            states: dict[Path, _FileState[T]] = {}
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
                    last_good = previous.item if previous is not None else None
                    keeping = "; keeping the last good version" if last_good is not None else ""
                    size = signature[1]
                    if size > kind.max_bytes:
                        message = size_limit_message(path, size, kind.max_bytes, kind.what)
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
                        item = kind.load(path, origin=origin)
                    except kind.error as exc:
                        skipped = keeping or "; skipped until the file is fixed"
                        self._report(f"file:{path}", str(exc), logging.WARNING, f"{exc}{skipped}")
                        states[path] = _FileState(origin, folder, signature, last_good, str(exc), recheck)
                    else:
                        self._resolve(f"file:{path}")
                        states[path] = _FileState(origin, folder, signature, item, None, recheck)
            for path in old.keys() - states.keys():  # gone: a new problem with it is news again
                self._resolve(f"file:{path}")
            if states.keys() == old.keys() and all(states[p] is old[p] for p in states):
                return {}
            return self._publish(states)

    def _publish(self, states: dict[Path, _FileState[T]]) -> dict[str, str]:
        items: dict[str, T] = {}
        ordered = sorted(states.items(), key=lambda entry: (entry[1].origin != "shipped", str(entry[0])))
        for path, state in ordered:  # shipped first, then user: user wins
            item = state.item
            if item is None:
                continue
            if item.name in items and items[item.name].origin == item.origin:
                self._report(
                    f"twice:{item.name}",
                    str(path),
                    logging.WARNING,
                    f"{path}: {self.kind.noun} {item.name!r} defined twice; using {items[item.name].path}",
                )
                continue
            items[item.name] = item
        errors = {str(p): s.error for p, s in ordered if s.error is not None}
        with self._lock:
            previous = self._items
            self._items, self._states, self.errors = items, states, errors
        changes: dict[str, str] = {}
        for name in previous.keys() | items.keys():
            if name not in items:
                changes[name] = "removed"
            elif name not in previous:
                changes[name] = "added"
            elif previous[name] != items[name]:
                changes[name] = "changed"
        return dict(sorted(changes.items()))

    # ----------------------------------------------------------------- queries
    def names(self) -> list[str]:
        """Sorted names."""
        with self._lock:
            return sorted(self._items)

    def items(self) -> list[T]:
        """Every effective item (preset, clip), sorted by name."""
        with self._lock:
            return [self._items[n] for n in sorted(self._items)]

    def __contains__(self, name: object) -> bool:
        with self._lock:
            return name in self._items

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def get(self, name: str) -> T:
        """An item by name.

        Raises
        ------
        VibsynthError
            ``kind.error`` with the file's own error when the file of that name is broken;
            ``kind.unknown`` for an unknown name (the message lists close names).
        """
        noun = self.kind.noun
        with self._lock:
            item = self._items.get(name)
            names = sorted(self._items)
            user = sum(1 for p in self._items.values() if p.origin == "user")
        if item is not None:
            return item
        suffix = self.kind.suffix
        broken = [message for path, message in self.errors.items() if Path(path).name == name + suffix]
        if broken:  # the file exists but is invalid: say what is wrong with it
            raise self.kind.error(broken[0])
        lowered = {n.lower(): n for n in names}
        near = [lowered[name.lower()]] if name.lower() in lowered else []
        near += [n for n in difflib.get_close_matches(name, names, n=4, cutoff=0.5) if n not in near]
        hint = f"; did you mean {', '.join(near)}?" if near else ""
        where = f"{len(names) - user} shipped, {user} in {self.user_dir}" if self.user_dir else "all shipped"
        raise self.kind.unknown(
            f"unknown {noun} {name!r}{hint} ({len(names)} {noun}s: {where}; `vibsynth {noun} list` shows them)"
        )

    def user_path(self, name: str) -> Path:
        """Where a user file of this name is (or would be) stored."""
        noun = self.kind.noun
        if not re.fullmatch(NAME_PATTERN, name):
            raise self.kind.error(f"{noun} name {name!r}: must be {NAME_RULE}")
        if self.user_dir is None:
            raise self.kind.error(f"no user {noun} folder configured ({self.kind.section}.user_dir)")
        return self.user_dir / f"{name}{self.kind.suffix}"

    def remove_user(self, name: str) -> tuple[Path, bool]:
        """Delete a user file (shipped ones are read-only; a broken file can be removed) and reload.

        Returns
        -------
        path : pathlib.Path
            The file removed.
        shipped_again : bool
            A shipped item of that name is used again.

        Raises
        ------
        VibsynthError
            ``kind.error`` for a name that is not a plain file name or a file that cannot be
            removed; ``kind.unknown`` for a shipped item, a name without a user file, or an
            unknown name (with "did you mean").
        """
        noun, suffix = self.kind.noun, self.kind.suffix
        target = self.user_path(name)
        if not target.is_file():
            if name in self and self.get(name).origin == "shipped":
                raise self.kind.unknown(f"{name!r} is a shipped {noun}: shipped {noun}s are read-only")
            self.get(name)  # unknown: "did you mean"
            raise self.kind.unknown(f"{name!r} has no file in the user folder {self.user_dir}")
        try:
            target.unlink()
        except OSError as exc:
            raise self.kind.error(f"{target}: cannot remove it ({exc.strerror or exc})") from None
        self.reload()
        shipped = self.shipped_dir is not None and (self.shipped_dir / f"{name}{suffix}").is_file()
        return target, shipped

    def save_user(self, item: T, *, overwrite: bool = False) -> Path:
        """Write an item into the user folder (atomically) and reload."""
        path = self.user_path(item.name)
        if path.exists() and not overwrite:
            raise self.kind.error(f"{path}: exists already (use --force to replace it)")
        self.kind.save(item, path)
        self.reload()
        return path


PRESETS: LibraryKind[Preset] = LibraryKind(
    noun="preset",
    what=WHAT,
    folder="presets",
    section="presets",
    load=load_preset,
    save=save_preset,
    error=PresetError,
    unknown=UnknownPresetError,
    max_bytes=MAX_PRESET_BYTES,
)


class PresetLibrary(FileLibrary[Preset]):
    """Shipped presets plus a user folder; a user preset overrides a shipped one of the same name.

    Parameters
    ----------
    shipped_dir : path-like or None
        Default: :func:`shipped_presets_dir`. None = no shipped presets (tests).
    user_dir : path-like or None
        User presets (need not exist yet).
    load : bool
        Read the folders now.

    See :class:`FileLibrary` for reloading and errors.
    """

    kind = PRESETS

    def presets(self) -> list[Preset]:
        """Every effective preset, sorted by name."""
        return self.items()

    def program_map(self) -> dict[int, str]:
        """MIDI program -> preset name.

        Presets with a ``program`` field take it (on a clash the user preset, then the
        first name, wins); the others fill the free numbers in name order.
        """
        presets = self.items()
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


def user_dir_of(settings: VibsynthConfig | None, kind: LibraryKind[T]) -> Path:
    """A kind's user folder for the typed settings: ``<section>.user_dir``, or the platform folder."""
    user_dir = getattr(settings, kind.section).user_dir if settings is not None else None
    return Path(user_dir).expanduser() if user_dir else default_user_dir(kind.folder)


def load_library(settings: VibsynthConfig | None = None) -> PresetLibrary:
    """The preset library for the settings: shipped presets + ``presets.user_dir`` (or the platform folder)."""
    return PresetLibrary(shipped_presets_dir(), user_dir_of(settings, PRESETS))


def _why(exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return "symbolic link loop"
    return exc.strerror or str(exc)


def iter_preset_files(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Preset files of a folder (sorted)."""
    return _files(Path(folder))
