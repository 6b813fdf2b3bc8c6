"""Recordings in and WAV renders out: read a WAV/CSV/text vibration recording, write a WAV.

Every reader validates at the edge and raises :class:`~vibsynth.errors.InputError` with a
message naming the file and the problem.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.files import atomic_write

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    pass

RECORDING_SUFFIXES = (".wav", ".csv", ".txt")


@dataclass(frozen=True)
class Recording:
    """A mono recording read from a file.

    Attributes
    ----------
    samples : ndarray, shape (n_samples,)
        float64; integer WAV data is scaled to [-1, 1) (8-bit and narrower: unsigned,
        centred at 128).
    fs : float
        Sample rate in Hz.
    path : pathlib.Path
    """

    samples: NDArray[np.float64]
    fs: float
    path: Path


def _scale_wav(data: NDArray[Any]) -> NDArray[np.float64]:
    """Samples as float64 in [-1, 1): float data as it is, integers by their container's full scale.

    A 1-byte container holds *unsigned* PCM centred at 128, whatever its bit depth (1..8
    bits, left-justified, as the WAV format defines): [0, 255] maps to [-1, 127/128].
    Wider containers are signed: divided by 2**(bits of the container - 1).
    """
    if data.dtype.itemsize == 1 and np.issubdtype(data.dtype, np.integer):
        return (data.view(np.uint8).astype(np.float64) - 128.0) / 128.0
    if np.issubdtype(data.dtype, np.integer):
        return data.astype(np.float64) / float(-np.iinfo(data.dtype).min)
    return data.astype(np.float64)


#: Chunks scanned for the ``fmt `` chunk before giving up (real files have it first or second).
_MAX_HEADER_CHUNKS = 64


def _wav_layout(path: Path) -> tuple[int, int, int] | None:
    """(channels, block_align, bits per sample) from a WAV's ``fmt `` chunk; None when not found.

    Raises :class:`~vibsynth.errors.InputError` when the file cannot be read.

    Only what :func:`_read_wav` checks before handing the file to scipy, which reads
    everything else (and refuses what it cannot read).
    """
    import struct

    try:
        with open(path, "rb") as handle:
            head = handle.read(12)
            if len(head) < 12 or head[:4] not in (b"RIFF", b"RIFX", b"RF64") or head[8:12] != b"WAVE":
                return None
            order = ">" if head[:4] == b"RIFX" else "<"
            for _ in range(_MAX_HEADER_CHUNKS):
                chunk = handle.read(8)
                if len(chunk) < 8:
                    return None
                size = struct.unpack(order + "I", chunk[4:])[0]
                if chunk[:4] == b"fmt ":
                    fmt = handle.read(16)
                    if len(fmt) < 16:
                        return None
                    _tag, channels, _fs, _rate, block_align, bits = struct.unpack(order + "HHIIHH", fmt)
                    return int(channels), int(block_align), int(bits)
                handle.seek(size + (size & 1), 1)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return None


def _read_wav(path: Path, channel: int) -> tuple[NDArray[np.float64], float]:
    from scipy.io import wavfile

    layout = _wav_layout(path)
    if layout is None:  # no RIFF/WAVE header or no fmt chunk: scipy would fail in its own ways
        raise InputError(f"{path}: not a readable WAV file (no RIFF/WAVE header with a 'fmt ' chunk)")
    channels, block_align, bits = layout
    if channels == 0:
        raise InputError(f"{path}: not a readable WAV file (its header says 0 channels)")
    if bits == 0 or block_align < channels:
        raise InputError(
            f"{path}: not a readable WAV file (its header says {bits} bits per sample, "
            f"{block_align} bytes per frame for {channels} channels)"
        )
    try:
        with warnings.catch_warnings():  # unknown chunks (e.g. LIST metadata) are harmless
            warnings.simplefilter("ignore", wavfile.WavFileWarning)
            fs, data = wavfile.read(path)
    except (ValueError, EOFError, OSError, IndexError, TypeError, ZeroDivisionError, MemoryError) as exc:
        raise InputError(f"{path}: not a readable WAV file ({exc})") from None
    samples = _scale_wav(np.asarray(data))
    if samples.ndim == 2:
        if not (0 <= channel < samples.shape[1]):
            raise InputError(
                f"{path}: has {samples.shape[1]} channels; channel {channel + 1} (index {channel}) does not exist"
            )
        samples = samples[:, channel]
    elif channel != 0:
        raise InputError(f"{path}: is mono; channel {channel + 1} (index {channel}) does not exist")
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


def write_wav(
    path: str | os.PathLike[str], samples: NDArray[Any], fs: float, *, sample_format: str = "float32"
) -> None:
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


def iter_recordings(folder: str | os.PathLike[str]) -> Iterable[Path]:
    """Recording files in a folder (sorted; .wav, .csv, .txt)."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in RECORDING_SUFFIXES)
