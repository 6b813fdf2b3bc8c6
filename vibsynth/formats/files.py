"""The two rules every file of vibsynth goes through: bounded reads and atomic writes.

* :func:`read_text` refuses a file over its size cap before reading it.
* :func:`atomic_write` is the one writer (presets, learned MIDI bindings, the bank cache,
  WAV renders, bases, plots, ``.vbt`` files): a temporary file in the same folder, flush +
  fsync, ``os.replace``, fsync of the folder. A crash leaves the old file or the new one,
  never part of one. New files get mode 0644 (the umask is respected).

The building blocks of that writer are public, one job each, for the other writer that
streams (:class:`vibsynth.formats.wav_stream.WavStreamWriter`): :func:`resolve_target`,
:func:`kept_mode`, :func:`create_temp_file`, :func:`remove_quietly`, :func:`fsync_folder`,
and :func:`check_writable` for commands that should refuse an unwritable folder up front.
"""

from __future__ import annotations

import errno
import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from vibsynth.errors import InputError

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    pass

#: What :func:`atomic_write` accepts: bytes, text (UTF-8) or ``writer(binary_file)``.
WriteData = bytes | bytearray | memoryview | str | Callable[[BinaryIO], object]

_TEMP_ATTEMPTS = 100


def create_temp_file(folder: Path, name: str) -> tuple[int, Path]:
    """Create a new, empty, hidden temporary file for ``name`` in ``folder``.

    The file is ``.<name>.<random>.tmp``: hidden, and not ending in the target's suffix,
    so folder listings (the preset library) never take it for a file of theirs. Mode
    0o666 is requested and the kernel applies the umask (0644 under the usual 022),
    unlike :func:`tempfile.mkstemp`, which always creates 0600.

    Parameters
    ----------
    folder : pathlib.Path
        Where the target will be (a rename is atomic only within one file system).
    name : str
        The target's file name.

    Returns
    -------
    fd : int
        Open for writing (``O_EXCL``, close-on-exec); the caller closes it.
    path : pathlib.Path
        The temporary file; the caller renames it over the target or removes it.

    Raises
    ------
    OSError
        The folder is missing or not writable; ``FileExistsError`` when 100 random names were taken.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    for _ in range(_TEMP_ATTEMPTS):
        tmp = folder / f".{name}.{secrets.token_hex(4)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary file name after {_TEMP_ATTEMPTS} tries", str(folder))


def fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (POSIX; a no-op where folders cannot be opened or fsynced).

    Parameters
    ----------
    folder : pathlib.Path
    """
    if not hasattr(os, "O_DIRECTORY"):
        return
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems (e.g. certain FUSE/CIFS) do not fsync folders: the rename stands
        pass
    finally:
        os.close(fd)


def remove_quietly(path: Path | None) -> None:
    """Remove a (temporary) file if it is there; ``None`` and every ``OSError`` are ignored.

    Parameters
    ----------
    path : pathlib.Path or None
    """
    if path is not None:
        try:
            os.unlink(path)
        except OSError:
            pass


def resolve_target(path: str | os.PathLike[str]) -> Path:
    """The file a writer replaces: ``~`` expanded, a symbolic link followed to the file it points to.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    target : pathlib.Path
    """
    target = Path(path).expanduser()
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    return target


def kept_mode(target: Path) -> int | None:
    """The permission bits a replacement of ``target`` keeps: its current mode, or None for a new file.

    A new file gets 0666 minus the umask (see :func:`create_temp_file`); a replaced
    file keeps its mode (a config someone made 0600 stays 0600).

    Parameters
    ----------
    target : pathlib.Path

    Returns
    -------
    mode : int or None
    """
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except FileNotFoundError:
        return None


def check_writable(folder: Path) -> None:
    """Prove that a file can be created in ``folder`` (created and removed at once).

    For commands that work a long time before they write (a long render, ``serve -o``):
    they refuse at the start instead of failing at the end.

    Parameters
    ----------
    folder : pathlib.Path

    Raises
    ------
    OSError
        The file cannot be created (read-only or missing folder, no permission); ``filename`` is the folder.
    """
    try:
        fd, tmp = create_temp_file(folder, "write-check")
    except OSError as exc:
        raise type(exc)(exc.errno, exc.strerror or str(exc), str(folder)) from None
    os.close(fd)
    remove_quietly(tmp)


def atomic_write(path: str | os.PathLike[str], data: WriteData) -> Path:
    """Write a file atomically; every file vibsynth writes goes through here.

    A temporary file is created in the target's folder (``.<name>.<random>.tmp``), written,
    flushed and fsynced, renamed over the target with :func:`os.replace`, and the folder is
    fsynced. A crash or ``kill -9`` at any moment leaves either the old file or the complete
    new one, never part of one; at worst a hidden ``.tmp`` file stays behind, which no
    vibsynth listing reads.

    Parameters
    ----------
    path : path-like
        Target file; its folder is created when missing. A symbolic link is written through
        (the file it points to is replaced; the link stays).
    data : bytes, str or callable
        The content (``str`` is written as UTF-8), or ``writer(fh)`` that writes to a binary
        file object: large content (the bank cache) is streamed, never built in memory first.

    Returns
    -------
    path : pathlib.Path
        The file written (the link's target for a symbolic link).

    Raises
    ------
    OSError
        The folder cannot be created or written (the message names the target). The
        temporary file is removed and the old file is untouched.

    Notes
    -----
    A new file gets mode 0666 minus the umask (0644 usually), like any file a program
    creates; a replaced file keeps its mode (a config someone made 0600 stays 0600).
    """
    target = resolve_target(path)
    folder = target.parent
    tmp: Path | None = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        mode = kept_mode(target)
        fd, tmp = create_temp_file(folder, target.name)
        with os.fdopen(fd, "wb") as handle:
            if callable(data):
                data(handle)
            else:
                handle.write(data.encode("utf-8") if isinstance(data, str) else data)
            handle.flush()
            if mode is not None and hasattr(os, "fchmod"):
                os.fchmod(handle.fileno(), mode)
            os.fsync(handle.fileno())
        os.replace(tmp, target)
        tmp = None
    except OSError as exc:
        remove_quietly(tmp)
        raise type(exc)(exc.errno, exc.strerror or str(exc), str(target)) from None  # name the target, not the temp
    except BaseException:  # a failing writer, KeyboardInterrupt: no temporary file left behind
        remove_quietly(tmp)
        raise
    fsync_folder(folder)
    return target


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write bytes atomically (see :func:`atomic_write`)."""
    atomic_write(path, bytes(data))


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 text atomically (see :func:`atomic_write`)."""
    atomic_write(path, text)


#: Size cap of a preset, a config file, an actuator profile (each a few KB; 1 MiB is
#: hundreds of times more than any real one). Larger files are refused before they are read.
MAX_YAML_BYTES = 1 << 20
#: Size cap of a basis file: the shipped one is 5.5 KB and a full 30-component basis with
#: a long provenance stays under 50 KB; 4 MiB leaves ample margin yet keeps a parse well
#: under a second.
MAX_BASIS_BYTES = 4 << 20
#: Deepest nesting allowed (mappings/lists inside each other). Real files nest 4 levels.
MAX_YAML_DEPTH = 64


def _size_text(n: int) -> str:
    if n >= 1 << 20 and n % (1 << 20) == 0:
        return f"{n >> 20} MiB"
    if n >= 1 << 10 and n % (1 << 10) == 0:
        return f"{n >> 10} KiB"
    return f"{n} bytes"


def size_limit_message(path: str | os.PathLike[str], size: int | None, max_bytes: int, what: str) -> str:
    """The one wording of "file too large" (also logged by the preset watcher); ``size`` None = unknown."""
    bytes_ = f"{size:,} bytes, over" if size is not None else "over"
    return f"{path}: {bytes_} the {_size_text(max_bytes)} limit for {what}; not read"


def _read_capped(path: Path, *, max_bytes: int, error: type[Exception], what: str) -> bytes:
    try:
        with open(path, "rb") as handle:
            info = os.fstat(handle.fileno())
            if stat.S_ISREG(info.st_mode) and info.st_size > max_bytes:
                raise error(size_limit_message(path, info.st_size, max_bytes, what))
            # never more than the cap + 1 byte, even if the file grows meanwhile (and no cap-sized
            # buffer for a small file: read(n) allocates n bytes up front)
            want = min(info.st_size, max_bytes) + 1 if stat.S_ISREG(info.st_mode) else max_bytes + 1
            data = handle.read(want)
            if len(data) == want and want <= max_bytes:  # grew since fstat: read on, up to the cap
                data += handle.read(max_bytes + 1 - want)
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, expected a file") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(data) > max_bytes:
        raise error(size_limit_message(path, None, max_bytes, what))  # grew while being read, or not a file
    return data


def read_text(
    path: str | os.PathLike[str],
    *,
    error: type[Exception] = InputError,
    max_bytes: int = MAX_YAML_BYTES,
    what: str = "a text file",
) -> str:
    """Read a UTF-8 text file of at most ``max_bytes``; every reason it cannot be read becomes one
    ``error`` naming the file.

    Parameters
    ----------
    path : path-like
    error : exception type
        Raised (with a one-line message) for a missing file, a folder, a file over the size
        cap (refused before reading it), non-UTF-8 bytes or any other OS error.
    max_bytes : int
        Size cap (default :data:`MAX_YAML_BYTES`).
    what : str
        What the file is, for the size message ("a preset", "a config file").
    """
    p = Path(path).expanduser()
    data = _read_capped(p, max_bytes=max_bytes, error=error, what=what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{p}: not a UTF-8 text file") from None
