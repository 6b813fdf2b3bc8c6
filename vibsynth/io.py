"""Files in and out: recordings, WAV renders, PSD tables, basis YAML, and the two rules every
file of vibsynth goes through.

* :func:`load_yaml` is the one YAML loader (config, presets, bases, actuator profiles, the
  round-trip load of MIDI learn). It refuses a file over its size cap before reading it,
  refuses YAML aliases (``*name``: a 381-byte "billion laughs" file expands to gigabytes)
  and nesting deeper than :data:`MAX_YAML_DEPTH`, naming ``file:line``.
* :func:`atomic_write` is the one writer (presets, learned MIDI bindings, the bank cache,
  WAV renders, bases, plots, ``.vbt`` files): a temporary file in the same folder, flush +
  fsync, ``os.replace``, fsync of the folder. A crash leaves the old file or the new one,
  never part of one.

Every reader validates at the edge and raises :class:`~vibsynth.errors.InputError` (or the
error type its caller asks for) with a message that names the file and the problem.
"""
from __future__ import annotations

import csv
import errno
import gzip
import os
import secrets
import stat
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Callable, Iterable, Union

import numpy as np
import yaml
from numpy.typing import NDArray
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from vibsynth.errors import InputError, ParameterError

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    from vibsynth.dsp.basis import Basis

__all__ = [
    "RECORDING_SUFFIXES",
    "Recording",
    "read_recording",
    "write_wav",
    "atomic_write",
    "atomic_write_text",
    "read_text",
    "atomic_write_bytes",
    "load_yaml",
    "dump_yaml",
    "LoadedYaml",
    "MAX_YAML_BYTES",
    "MAX_BASIS_BYTES",
    "MAX_YAML_DEPTH",
    "size_limit_message",
    "PsdTable",
    "read_psd_table",
    "load_basis",
    "save_basis",
    "default_basis",
    "DEFAULT_BASIS_RESOURCE",
]

RECORDING_SUFFIXES = (".wav", ".csv", ".txt")
DEFAULT_BASIS_RESOURCE = "default_basis.yaml"


@dataclass(frozen=True)
class Recording:
    """A mono recording read from a file.

    Attributes
    ----------
    samples : ndarray, shape (n_samples,)
        float64; integer WAV data is scaled to [-1, 1).
    fs : float
        Sample rate in Hz.
    path : pathlib.Path
    """

    samples: NDArray[np.float64]
    fs: float
    path: Path


def _scale_wav(data: NDArray[Any]) -> NDArray[np.float64]:
    if data.dtype == np.uint8:
        return (data.astype(np.float64) - 128.0) / 128.0
    if np.issubdtype(data.dtype, np.integer):
        return data.astype(np.float64) / float(-np.iinfo(data.dtype).min)
    return data.astype(np.float64)


def _read_wav(path: Path, channel: int) -> tuple[NDArray[np.float64], float]:
    from scipy.io import wavfile

    try:
        with warnings.catch_warnings():  # unknown chunks (e.g. LIST metadata) are harmless
            warnings.simplefilter("ignore", wavfile.WavFileWarning)
            fs, data = wavfile.read(path)
    except (ValueError, EOFError, OSError, IndexError, TypeError) as exc:
        raise InputError(f"{path}: not a readable WAV file ({exc})") from None
    samples = _scale_wav(np.asarray(data))
    if samples.ndim == 2:
        if not (0 <= channel < samples.shape[1]):
            raise InputError(f"{path}: has {samples.shape[1]} channels, channel {channel} does not exist")
        samples = samples[:, channel]
    elif channel != 0:
        raise InputError(f"{path}: is mono, channel {channel} does not exist")
    return samples, float(fs)


def _read_text_column(path: Path, fs: float | None) -> tuple[NDArray[np.float64], float]:
    if fs is None:
        raise InputError(f"{path}: CSV/TXT recordings carry no sample rate; give it with --rate HZ")
    values: list[float] = []
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            for line_no, line in enumerate(handle, start=1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                first = text.replace(";", ",").replace("\t", ",").split(",")[0].strip()
                try:
                    values.append(float(first))
                except ValueError:
                    if values:  # a header is only allowed before the data
                        raise InputError(f"{path}:{line_no}: not a number: {first!r}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None
    return np.asarray(values, dtype=np.float64), float(fs)


def read_recording(path: str | os.PathLike[str], *, fs: float | None = None, channel: int = 0) -> Recording:
    """Read a recording: WAV (any PCM or float), or CSV/TXT with one column of samples.

    Parameters
    ----------
    path : path-like
    fs : float, optional
        Sample rate for CSV/TXT (required there; ignored for WAV).
    channel : int
        Channel to take from a multi-channel WAV.

    Returns
    -------
    recording : Recording

    Raises
    ------
    InputError
        Missing, unreadable, unsupported, empty, or containing NaN/inf samples.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    if p.is_dir():
        raise InputError(f"{p}: is a folder, expected a recording file")
    suffix = p.suffix.lower()
    if suffix == ".wav":
        samples, rate = _read_wav(p, channel)
    elif suffix in (".csv", ".txt"):
        samples, rate = _read_text_column(p, fs)
    else:
        raise InputError(f"{p}: unsupported file type {suffix or '(none)'}; use .wav, .csv or .txt")
    if samples.size == 0:
        raise InputError(f"{p}: contains no samples")
    if not np.all(np.isfinite(samples)):
        bad = int(np.count_nonzero(~np.isfinite(samples)))
        raise InputError(f"{p}: {bad} samples are NaN or infinite")
    if not np.isfinite(rate) or rate <= 0:
        raise InputError(f"{p}: invalid sample rate {rate}")
    return Recording(samples=samples, fs=rate, path=p)


# --------------------------------------------------------------------------- atomic writes
#: What :func:`atomic_write` accepts: bytes, text (UTF-8) or ``writer(binary_file)``.
WriteData = Union[bytes, bytearray, memoryview, str, Callable[[BinaryIO], object]]

_TEMP_ATTEMPTS = 100


def _temp_file(folder: Path, name: str) -> tuple[int, Path]:
    """Create ``.<name>.<random>.tmp`` in ``folder``: hidden, and not ending in the target's suffix,
    so folder listings (the preset library) never take it for a file of theirs.

    Mode 0o666 is requested and the kernel applies the umask (0644 under the usual 022),
    unlike :func:`tempfile.mkstemp`, which always creates 0600.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    for _ in range(_TEMP_ATTEMPTS):
        tmp = folder / f".{name}.{secrets.token_hex(4)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary file name after {_TEMP_ATTEMPTS} tries", str(folder))


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (POSIX; a no-op where folders cannot be opened)."""
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
    target = Path(path).expanduser()
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    folder = target.parent
    tmp: Path | None = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        try:
            mode: int | None = stat.S_IMODE(os.stat(target).st_mode)
        except FileNotFoundError:
            mode = None
        fd, tmp = _temp_file(folder, target.name)
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
        _remove_quietly(tmp)
        raise type(exc)(exc.errno, exc.strerror or str(exc), str(target)) from None  # name the target, not the temp
    except BaseException:  # a failing writer, KeyboardInterrupt: no temporary file left behind
        _remove_quietly(tmp)
        raise
    _fsync_folder(folder)
    return target


def _remove_quietly(tmp: Path | None) -> None:
    if tmp is not None:
        try:
            os.unlink(tmp)
        except OSError:
            pass


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write bytes atomically (see :func:`atomic_write`)."""
    atomic_write(path, bytes(data))


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 text atomically (see :func:`atomic_write`)."""
    atomic_write(path, text)


def write_wav(path: str | os.PathLike[str], samples: NDArray[Any], fs: float, *, sample_format: str = "float32") -> None:
    """Write a WAV file atomically.

    Parameters
    ----------
    path : path-like
    samples : ndarray, shape (n_samples,) or (n_samples, n_channels)
        Values in [-1, 1].
    fs : float
        Sample rate (rounded to an integer, as WAV requires).
    sample_format : {"float32", "pcm16"}

    Raises
    ------
    OSError
        The file cannot be written (see :func:`atomic_write`).
    """
    from scipy.io import wavfile

    data = np.asarray(samples)
    if sample_format == "float32":
        out = data.astype(np.float32)
    elif sample_format == "pcm16":
        out = np.round(np.clip(data, -1.0, 32767 / 32768) * 32768).astype(np.int16)
    else:
        raise ParameterError(f"unknown sample format {sample_format!r}; use float32 or pcm16")
    atomic_write(path, lambda handle: wavfile.write(handle, int(round(fs)), out))


@dataclass(frozen=True)
class PsdTable:
    """A table of one-sided PSDs (one row per spectrum).

    Attributes
    ----------
    freqs_hz : ndarray, shape (n_freqs,)
    psd : ndarray, shape (n_rows, n_freqs)
    labels : list of str
        First column (e.g. texture name) of each row.
    meta : list of dict
        Other non-frequency columns of each row (e.g. speed, force), as strings.
    """

    freqs_hz: NDArray[np.float64]
    psd: NDArray[np.float64]
    labels: list[str]
    meta: list[dict[str, str]]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_psd_table(path: str | os.PathLike[str]) -> PsdTable:
    """Read a PSD table (CSV, optionally gzipped) like ``hatt-psd/psd.csv.gz``.

    Columns whose header is a number are frequencies in Hz; the first other
    column is the label, the rest are kept as metadata.

    Raises
    ------
    InputError
        Missing file, no frequency columns, ragged rows, non-numeric or non-positive PSD values.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    opener = gzip.open if p.suffix == ".gz" else open
    try:
        with opener(p, "rt", newline="", encoding="utf-8") as handle:  # type: ignore[operator]
            reader = csv.reader(handle)
            header = next(reader)
            freq_cols = [i for i, h in enumerate(header) if _is_number(h)]
            other_cols = [i for i, h in enumerate(header) if not _is_number(h)]
            if len(freq_cols) < 2:
                raise InputError(f"{p}: no frequency columns (headers that are numbers in Hz)")
            rows, labels, meta = [], [], []
            for line_no, row in enumerate(reader, start=2):
                if len(row) != len(header):
                    raise InputError(f"{p}:{line_no}: has {len(row)} fields, header has {len(header)}")
                try:
                    rows.append([float(row[i]) for i in freq_cols])
                except ValueError:
                    raise InputError(f"{p}:{line_no}: PSD value is not a number") from None
                labels.append(row[other_cols[0]] if other_cols else str(line_no))
                meta.append({header[i]: row[i] for i in other_cols[1:]})
    except (OSError, EOFError, StopIteration, UnicodeDecodeError, gzip.BadGzipFile) as exc:
        raise InputError(f"{p}: cannot read PSD table ({exc})") from None
    psd = np.asarray(rows, dtype=np.float64)
    freqs = np.asarray([float(header[i]) for i in freq_cols])
    if psd.size == 0:
        raise InputError(f"{p}: has no rows")
    if not np.all(np.isfinite(psd)) or np.any(psd <= 0):
        raise InputError(f"{p}: PSD values must be finite and positive")
    return PsdTable(freqs_hz=freqs, psd=psd, labels=labels, meta=meta)


# --------------------------------------------------------------------------- reading text and YAML
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


def read_text(path: str | os.PathLike[str], *, error: type[Exception] = InputError,
              max_bytes: int = MAX_YAML_BYTES, what: str = "a text file") -> str:
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
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            line = self._anchor_lines.get(event.anchor)
            where = f" (anchor '&{event.anchor}' on line {line})" if line else ""
            raise _Refused(f"{event.start_mark.line + 1}:{event.start_mark.column + 1}: YAML alias "
                           f"'*{event.anchor}'{where}: aliases are not allowed in {self._what} (they can "
                           "expand a small file into gigabytes); write the value out instead")
        if self._depth >= self._max_depth:
            raise _Refused(f"{event.start_mark.line + 1}:{event.start_mark.column + 1}: nested more than "
                           f"{self._max_depth} levels deep (not allowed in {self._what})")
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            self._anchor_lines.setdefault(anchor, event.start_mark.line + 1)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


try:  # libyaml's parser when PyYAML was built with it (fast), else PyYAML's own
    from yaml.cyaml import CParser as _CParser

    class _GuardedLoader(_GuardedComposer, _CParser, SafeConstructor, Resolver):  # type: ignore[misc]
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
    return yaml.dump(data, Dumper=_NoAliasDumper, **options)


# --------------------------------------------------------------------------- basis files
_BASIS_HEADER = """\
# vibsynth spectral basis: mean spectrum M and principal components V1..V8
# of level-normalised 30-band dB spectra (see docs/science.md).
# Written by `vibsynth basis fit`; numbers rounded to 8 decimals.
"""


def save_basis(basis: Basis, path: str | os.PathLike[str]) -> None:
    """Write a basis as YAML, atomically.

    Raises
    ------
    InputError
        The file cannot be written (the message names it).
    """
    text = _BASIS_HEADER + dump_yaml(basis.to_dict(), sort_keys=False, width=120, default_flow_style=None)
    try:
        atomic_write(path, text)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None


def load_basis(path: str | os.PathLike[str]) -> Basis:
    """Read a basis YAML file (at most :data:`MAX_BASIS_BYTES`; see :func:`load_yaml`).

    Raises
    ------
    InputError
        Missing or oversized file, YAML syntax error, alias, or invalid basis (the message names the file).
    """
    loaded = load_yaml(path, error=InputError, what="a basis file", max_bytes=MAX_BASIS_BYTES)
    return _basis_from_data(loaded.data, loaded.origin)


def _basis_from_data(data: Any, name: str) -> Basis:
    from vibsynth.dsp.basis import Basis

    if not isinstance(data, dict):
        raise InputError(f"{name}: expected a mapping of basis fields")
    try:
        return Basis.from_dict(data)
    except ParameterError as exc:
        raise InputError(f"{name}: {exc}") from None


_DEFAULT_BASIS: Basis | None = None


def default_basis() -> Basis:
    """The basis shipped with the package (fitted from the HaTT spectra; cached)."""
    global _DEFAULT_BASIS
    if _DEFAULT_BASIS is None:
        text = resources.files("vibsynth.data").joinpath(DEFAULT_BASIS_RESOURCE).read_text(encoding="utf-8")
        name = f"vibsynth/data/{DEFAULT_BASIS_RESOURCE}"
        loaded = load_yaml(text=text, origin=name, what="a basis file", max_bytes=MAX_BASIS_BYTES)
        _DEFAULT_BASIS = _basis_from_data(loaded.data, name)
    return _DEFAULT_BASIS


def iter_recordings(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Recording files in a folder (sorted; .wav, .csv, .txt)."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in RECORDING_SUFFIXES)
