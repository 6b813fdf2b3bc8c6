"""A WAV file written block by block: header first, samples appended, sizes patched on close.

:class:`WavStreamWriter` writes the same bytes as :func:`vibsynth.formats.recordings.write_wav`
(``scipy.io.wavfile.write``: ``fmt`` chunk, a ``fact`` chunk for float data, RF64 above
4 GiB) without ever holding the samples: memory stays at one block whatever the length.

Atomic, by the rule of :func:`vibsynth.formats.files.atomic_write`: the samples go to a
temporary file in the target's folder, which is flushed, fsynced and renamed over the
target only by :meth:`WavStreamWriter.close`. :meth:`~WavStreamWriter.abort` (and any
exception inside a ``with`` block) removes it: an error or Ctrl-C mid-render leaves
neither a partial file nor a temporary one, and an existing target stays untouched.
On Linux the temporary file is anonymous (``O_TMPFILE``) until the commit, so even a
``kill -9`` or a power cut during an hour-long render leaves nothing behind; elsewhere
it is a hidden ``.<name>.<random>.tmp`` (like ``atomic_write``). A new file gets mode
0666 minus the umask (0644 usually); a replaced file keeps its mode.
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import struct
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import ParameterError
from vibsynth.formats.files import (
    check_writable,
    create_temp_file,
    fsync_folder,
    kept_mode,
    remove_quietly,
    resolve_target,
)

__all__ = ["WavStreamWriter", "SAMPLE_FORMATS", "encode_samples", "check_target"]

#: WAV sample formats: name -> (numpy dtype written, WAVE format tag).
SAMPLE_FORMATS: dict[str, tuple[np.dtype[Any], int]] = {
    "float32": (np.dtype("<f4"), 3),  # WAVE_FORMAT_IEEE_FLOAT
    "pcm16": (np.dtype("<i2"), 1),  # WAVE_FORMAT_PCM
}

_U32_MAX = 0xFFFFFFFF
_WRITE_BUFFER = 1 << 20


def encode_samples(samples: NDArray[np.floating[Any]], sample_format: str) -> NDArray[np.float32] | NDArray[np.int16]:
    """Samples as stored in the file: float32, or pcm16 clipped to [-1, 32767/32768] and rounded.

    Element by element, so a block gives the same values as the whole signal
    (the conversion of :func:`~vibsynth.formats.recordings.write_wav`).

    Parameters
    ----------
    samples : ndarray, shape (n_frames,) or (n_frames, n_channels)
        Float samples, nominally in [-1, 1].
    sample_format : {"float32", "pcm16"}

    Returns
    -------
    data : ndarray, same shape, little-endian float32 or int16
    """
    data = np.asarray(samples)
    if sample_format == "float32":
        return data.astype(np.dtype("<f4"), copy=False)
    if sample_format == "pcm16":  # typed dtypes: the result's type is known (not Any) to strict callers
        return np.round(np.clip(data, -1.0, 32767 / 32768) * 32768).astype(np.dtype("<i2"))
    raise ParameterError(f"unknown sample format {sample_format!r}; use float32 or pcm16")


def check_target(path: str | os.PathLike[str], *, make_folder: bool = False, writable: bool = False) -> Path:
    """Refuse an output path before any work: its folder must exist and it must not be a folder.

    Parameters
    ----------
    path : path-like
    make_folder : bool
        A missing folder is fine (it will be created).
    writable : bool
        Also prove that a file can be created in the folder
        (:func:`~vibsynth.formats.files.check_writable`): a read-only folder is refused
        before a long render instead of after it.

    Returns
    -------
    target : pathlib.Path
        The file that will be written (a symbolic link's target).

    Raises
    ------
    FileNotFoundError
        The folder does not exist; ``filename`` is the folder, ``strerror`` "folder does not exist".
    IsADirectoryError
        ``path`` is a folder.
    OSError
        With ``writable``: no file can be created in the folder (``filename`` is the folder).
    """
    target = resolve_target(path)
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder, expected a file name", str(target))
    folder = target.parent
    if not folder.is_dir():
        if not make_folder:
            raise FileNotFoundError(errno.ENOENT, "folder does not exist", str(folder))
    elif writable:
        check_writable(folder)
    return target


def _open_anonymous(folder: Path) -> int | None:
    """An unnamed file in ``folder`` (Linux ``O_TMPFILE``) that can be linked in later, else None."""
    flag = getattr(os, "O_TMPFILE", 0)
    if not flag or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(folder, flag | os.O_RDWR | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError:  # file system without O_TMPFILE support (EOPNOTSUPP, EISDIR on old kernels)
        return None


def _name_anonymous(fd: int, folder: Path, name: str) -> Path:
    """Give the unnamed file ``fd`` a hidden temporary name in ``folder`` (its content, fsynced).

    ``linkat(AT_SYMLINK_FOLLOW)`` of ``/proc/self/fd/N`` (``os.link`` only calls ``linkat``
    when given a folder descriptor); where that is refused, the content is copied into a
    named temporary file instead.
    """
    dir_fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        for _ in range(100):
            tmp = folder / f".{name}.{secrets.token_hex(4)}.tmp"
            try:
                os.link(f"/proc/self/fd/{fd}", tmp.name, dst_dir_fd=dir_fd, follow_symlinks=True)
            except FileExistsError:
                continue
            except OSError:
                break
            return tmp
    finally:
        os.close(dir_fd)
    out_fd, tmp = create_temp_file(folder, name)
    try:
        with os.fdopen(out_fd, "wb") as out, os.fdopen(os.dup(fd), "rb") as src:
            src.seek(0)
            shutil.copyfileobj(src, out, _WRITE_BUFFER)
            out.flush()
            os.fsync(out.fileno())
    except BaseException:
        remove_quietly(tmp)
        raise
    return tmp


class WavStreamWriter:
    """Write a WAV file block by block, atomically.

    Parameters
    ----------
    path : path-like
        Target file. A symbolic link is written through (like ``atomic_write``).
    fs : float
        Sample rate (rounded to an integer, as WAV requires).
    channels : int
    sample_format : {"float32", "pcm16"}
    frames : int, optional
        Expected number of frames. Only decides between a RIFF and an RF64 header
        (above 4 GiB), as ``scipy.io.wavfile.write`` does for the whole array; the sizes
        are patched from what was actually written. Without it the file is RIFF and
        :meth:`close` refuses to go past 4 GiB.
    make_folder : bool
        Create a missing folder (default: refuse, see Raises).
    anonymous : bool
        Use an anonymous temporary file where the system has one (``O_TMPFILE``).

    Raises
    ------
    FileNotFoundError
        The target's folder does not exist (and ``make_folder`` is false); ``filename`` is the folder.
    IsADirectoryError
        The target is a folder.
    OSError
        The temporary file cannot be created.
    ParameterError
        Bad rate, channel count or sample format.

    Notes
    -----
    Use it as a context manager, or call :meth:`close` (commit) or :meth:`abort`
    (discard) exactly once; leaving a ``with`` block without :meth:`close` aborts.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        fs: float,
        channels: int,
        *,
        sample_format: str = "float32",
        frames: int | None = None,
        make_folder: bool = False,
        anonymous: bool = True,
    ) -> None:
        if sample_format not in SAMPLE_FORMATS:
            raise ParameterError(f"unknown sample format {sample_format!r}; use float32 or pcm16")
        rate = int(round(fs))
        if not 1 <= rate <= _U32_MAX:
            raise ParameterError(f"sample rate must be a positive integer for WAV, got {fs!r}")
        if int(channels) != channels or not 1 <= channels <= 0xFFFF:
            raise ParameterError(f"channels must be an integer in 1..65535, got {channels!r}")
        target = check_target(path, make_folder=make_folder)
        folder = target.parent
        if make_folder:
            folder.mkdir(parents=True, exist_ok=True)
        self.path = target
        self.fs = rate
        self.channels = int(channels)
        self.sample_format = sample_format
        self.frames = 0
        self._dtype, tag = SAMPLE_FORMATS[sample_format]
        self._frame_bytes = self._dtype.itemsize * self.channels
        self._is_float = tag == 3
        self._header, self._rf64, self._fact_at, self._data_size_at = self._build_header(tag, frames)
        self._mode = kept_mode(target)
        self._tmp: Path | None = None
        fd = _open_anonymous(folder) if anonymous else None
        self._anonymous = fd is not None
        if fd is None:
            fd, self._tmp = create_temp_file(folder, target.name)
        self._fh: BinaryIO | None = None
        try:
            self._fh = os.fdopen(fd, "wb", buffering=_WRITE_BUFFER)
            self._fh.write(self._header)
        except BaseException:
            self._discard()
            raise

    # ------------------------------------------------------------------ header
    def _build_header(self, tag: int, frames: int | None) -> tuple[bytes, bool, int, int]:
        """Header bytes as ``scipy.io.wavfile.write`` lays them out; offsets of the fields to patch."""
        bits = self._dtype.itemsize * 8
        fmt = struct.pack("<HHIIHH", tag, self.channels, self.fs, self.fs * self._frame_bytes, self._frame_bytes, bits)
        if self._is_float:
            fmt += b"\x00\x00"  # cbSize for non-PCM formats
        riff = b"RIFF\x00\x00\x00\x00WAVEfmt " + struct.pack("<I", len(fmt)) + fmt
        expected = (frames or 0) * self._frame_bytes
        rf64 = len(riff) + 8 + expected - 8 > _U32_MAX
        header = riff
        if rf64:
            header = b"RF64\xff\xff\xff\xffWAVEds64" + struct.pack("<IQQQI", 28, 0, 0, 0, 0)
            header += b"fmt " + struct.pack("<I", len(fmt)) + fmt
        fact_at = -1
        if self._is_float:
            fact_at = len(header) + 8
            header += b"fact" + struct.pack("<II", 4, 0)
        data_size_at = len(header) + 4
        header += b"data\x00\x00\x00\x00"
        return header, rf64, fact_at, data_size_at

    # ------------------------------------------------------------------ writing
    def write(self, samples: NDArray[np.floating[Any]]) -> None:
        """Append frames.

        Parameters
        ----------
        samples : ndarray, shape (n_frames,) or (n_frames, channels)
            Float samples; converted like :func:`~vibsynth.formats.recordings.write_wav`.

        Raises
        ------
        OSError
            The write failed (disk full, file size limit); ``filename`` is the target.
            The writer stays open: :meth:`abort` it.
        """
        if self._fh is None:
            raise ValueError("the WAV writer is closed")
        block = np.asarray(samples)
        if block.ndim == 1:
            block = block[:, np.newaxis]
        if block.ndim != 2 or block.shape[1] != self.channels:
            raise ParameterError(f"expected blocks of shape (frames, {self.channels}), got {np.shape(samples)}")
        if block.shape[0] == 0:
            return
        data = np.ascontiguousarray(encode_samples(block, self.sample_format))
        try:
            self._fh.write(data.data.cast("B"))
        except OSError as exc:  # disk full, file too large: name the target, not the temporary file
            raise type(exc)(exc.errno, exc.strerror or str(exc), str(self.path)) from None
        self.frames += block.shape[0]

    def close(self) -> Path:
        """Patch the sizes, fsync and move the file into place. Returns the path written.

        Raises
        ------
        OSError
            Writing or renaming failed; nothing is left behind and the old file is untouched.
        ParameterError
            Over 4 GiB of samples without an RF64 header (pass ``frames``); nothing is written.
        """
        if self._fh is None:
            raise ValueError("the WAV writer is closed")
        try:
            self._finish()
        except OSError as exc:
            self._discard()
            raise type(exc)(exc.errno, exc.strerror or str(exc), str(self.path)) from None
        except BaseException:
            self._discard()
            raise
        fsync_folder(self.path.parent)
        return self.path

    def _finish(self) -> None:
        fh = self._fh
        assert fh is not None
        data_bytes = self.frames * self._frame_bytes
        riff_size = len(self._header) + data_bytes - 8
        if not self._rf64 and riff_size > _U32_MAX:
            raise ParameterError(f"{self.path}: over 4 GiB of samples needs an RF64 header (give frames=)")
        if self._rf64:
            fh.seek(20)
            fh.write(struct.pack("<QQQ", riff_size, data_bytes, self.frames))
        else:
            fh.seek(4)
            fh.write(struct.pack("<I", riff_size))
        if self._fact_at >= 0:
            fh.seek(self._fact_at)
            fh.write(struct.pack("<I", min(self.frames, _U32_MAX)))
        fh.seek(self._data_size_at)
        fh.write(struct.pack("<I", min(data_bytes, _U32_MAX)))
        fh.flush()
        if self._mode is not None and hasattr(os, "fchmod"):
            os.fchmod(fh.fileno(), self._mode)
        os.fsync(fh.fileno())
        if self._anonymous:  # give the unnamed file a (hidden) name, then rename it over the target
            self._tmp = _name_anonymous(fh.fileno(), self.path.parent, self.path.name)
        fh.close()
        self._fh = None
        assert self._tmp is not None
        os.replace(self._tmp, self.path)
        self._tmp = None

    def abort(self) -> None:
        """Discard everything written (no file, no temporary file); the old target stays. Idempotent."""
        self._discard()

    def _discard(self) -> None:
        fh, self._fh = self._fh, None
        if fh is not None:
            try:
                fh.close()
            except OSError:
                pass
        remove_quietly(self._tmp)
        self._tmp = None

    @property
    def closed(self) -> bool:
        """True once committed or aborted."""
        return self._fh is None

    def __enter__(self) -> WavStreamWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if not self.closed:
            self.abort()

    def __del__(self) -> None:  # a writer dropped without close/abort: discard, never commit
        try:
            self._discard()
        except Exception:
            pass
