"""Files in and out: recordings, WAV renders, PSD tables and basis YAML.

Every reader validates at the edge and raises :class:`~vibsynth.errors.InputError`
with a message that names the file and the problem.
"""
from __future__ import annotations

import csv
import gzip
import io as _io
import os
import tempfile
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.io import wavfile

from vibsynth.dsp.basis import Basis
from vibsynth.errors import InputError, ParameterError

__all__ = [
    "RECORDING_SUFFIXES",
    "Recording",
    "read_recording",
    "write_wav",
    "atomic_write_text",
    "read_text",
    "atomic_write_bytes",
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


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write a file atomically: a temporary file in the same folder, then rename."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 text atomically (see :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode("utf-8"))


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
    """
    data = np.asarray(samples)
    if sample_format == "float32":
        out = data.astype(np.float32)
    elif sample_format == "pcm16":
        out = np.round(np.clip(data, -1.0, 32767 / 32768) * 32768).astype(np.int16)
    else:
        raise ParameterError(f"unknown sample format {sample_format!r}; use float32 or pcm16")
    buffer = _io.BytesIO()
    wavfile.write(buffer, int(round(fs)), out)
    atomic_write_bytes(path, buffer.getvalue())


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


_BASIS_HEADER = """\
# vibsynth spectral basis: mean spectrum M and principal components V1..V8
# of level-normalised 30-band dB spectra (see docs/science.md).
# Written by `vibsynth basis fit`; numbers rounded to 8 decimals.
"""


def save_basis(basis: Basis, path: str | os.PathLike[str]) -> None:
    """Write a basis as YAML, atomically."""
    text = _BASIS_HEADER + yaml.safe_dump(basis.to_dict(), sort_keys=False, width=120, default_flow_style=None)
    atomic_write_text(path, text)


def read_text(path: str | os.PathLike[str], *, error: type[Exception] = InputError) -> str:
    """Read a UTF-8 text file; every reason it cannot be read becomes one ``error`` naming the file.

    Parameters
    ----------
    path : path-like
    error : exception type
        Raised (with a one-line message) for a missing file, a folder, non-UTF-8 bytes
        or any other OS error.
    """
    p = Path(path).expanduser()
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{p}: no such file") from None
    except IsADirectoryError:
        raise error(f"{p}: is a folder, expected a file") from None
    except UnicodeDecodeError:
        raise error(f"{p}: not a UTF-8 text file") from None
    except OSError as exc:
        raise error(f"{p}: cannot read ({exc.strerror})") from None


def load_basis(path: str | os.PathLike[str]) -> Basis:
    """Read a basis YAML file.

    Raises
    ------
    InputError
        Missing file, YAML syntax error or invalid basis (the message names the file).
    """
    return _basis_from_text(read_text(path), str(Path(path)))


def _basis_from_text(text: str, name: str) -> Basis:
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{name}: YAML error: {exc}") from None
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
        _DEFAULT_BASIS = _basis_from_text(text, f"vibsynth/data/{DEFAULT_BASIS_RESOURCE}")
    return _DEFAULT_BASIS


def iter_recordings(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Recording files in a folder (sorted; .wav, .csv, .txt)."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in RECORDING_SUFFIXES)
