"""A WAV file read block by block: the header checked against the file, samples as float64 frames.

:class:`WavReader` is the streaming twin of :class:`~vibsynth.formats.wav_stream.WavStreamWriter`:
memory stays at one block whatever the length, so an hour of 8-channel 192 kHz audio is read
in a few megabytes. It takes what real files hold: PCM 8 (unsigned), 16, 24 and 32 bit, IEEE
float 32 and 64 bit, ``WAVE_FORMAT_EXTENSIBLE`` of either, RIFF and RF64 (over 4 GiB).

Everything is checked before the first sample is handed out, and each problem is one
:class:`~vibsynth.errors.InputError` line naming the file: not a WAV, a format it cannot
decode, a channel count or rate out of bounds, a header claiming more samples than the file
holds (a truncated copy, or a garbage header claiming terabytes), no samples at all. NaN or
infinite samples in a float file are refused when the block holding them is read, with the
time of the first one.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, TypeVar

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError

__all__ = ["BlockReader", "WavReader", "MAX_WAV_CHANNELS", "MAX_WAV_RATE", "MIN_WAV_RATE"]

#: Most channels taken (a 7.1.4 mix is 12; ambisonics of order 7 is 64).
MAX_WAV_CHANNELS = 64
#: Highest sample rate taken (DXD / 8x rates are 352.8 and 384 kHz).
MAX_WAV_RATE = 768_000
#: Lowest sample rate taken (a haptic track's 80-200 Hz band needs well over 400 Hz).
MIN_WAV_RATE = 1_000
#: Chunks scanned for ``fmt `` and ``data`` before giving up (real files have a handful).
MAX_CHUNKS = 64

_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE
_DTYPES = {(_PCM, 16): "<i2", (_PCM, 32): "<i4", (_FLOAT, 32): "<f4", (_FLOAT, 64): "<f8"}


def _size(n: int) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} bytes"


_Reader = TypeVar("_Reader", bound="BlockReader")


class BlockReader:
    """What every sound reader shares: ``seconds``, :meth:`blocks` and the context manager.

    A subclass sets ``fs`` and ``frames`` and defines ``read(frames)`` and ``close()``
    (:class:`WavReader`, :class:`~vibsynth.formats.sound_reader.SoundFileReader`).
    """

    path: Path
    fs: float
    channels: int
    frames: int
    sample_format: str
    position: int

    @property
    def seconds(self) -> float:
        return self.frames / self.fs

    def read(self, frames: int) -> NDArray[np.float64]:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def _fail(self, why: str) -> InputError:
        return InputError(f"{self.path}: {why}")

    def _refuse_non_finite(self, x: NDArray[np.float64]) -> None:
        """Raise for a block (read at ``position``) holding NaN or infinity, naming the first one's time."""
        if not np.isfinite(x).all():
            bad = int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])
            t = (self.position + bad) / self.fs
            raise self._fail(f"NaN or infinite sample at {t:.3f} s (frame {self.position + bad:,}); not used")

    def blocks(self, frames: int) -> Iterator[NDArray[np.float64]]:
        """Every remaining frame, in blocks of ``frames`` (the last may be shorter)."""
        while True:
            block = self.read(frames)
            if block.shape[0] == 0:
                return
            yield block

    def __enter__(self: _Reader) -> _Reader:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class WavReader(BlockReader):
    """Read a WAV file in blocks of frames.

    Parameters
    ----------
    path : path-like

    Attributes
    ----------
    path : pathlib.Path
    fs : float
        Sample rate (Hz).
    channels : int
    frames : int
        Frames in the file.
    sample_format : str
        ``"pcm8"``, ``"pcm16"``, ``"pcm24"``, ``"pcm32"``, ``"float32"`` or ``"float64"``.
    position : int
        Frames read so far.

    Raises
    ------
    InputError
        Missing or unreadable file, not a WAV file, an encoding it does not decode, channels
        or rate out of bounds, a header that does not match the file, no samples.

    Notes
    -----
    Use it as a context manager (or call :meth:`close`).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise InputError(f"{self.path}: is a folder, expected a WAV file")
        try:
            self._fh: BinaryIO | None = open(self.path, "rb")
        except OSError as exc:
            raise InputError(f"{self.path}: cannot read ({exc.strerror or exc})") from None
        try:
            self._parse()
        except BaseException:
            self.close()
            raise
        self.position = 0

    # ------------------------------------------------------------------ header
    def _parse(self) -> None:
        fh = self._fh
        assert fh is not None
        file_size = os.fstat(fh.fileno()).st_size
        head = fh.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64", b"RIFX") or head[8:12] != b"WAVE":
            raise self._fail("not a WAV file (no RIFF/WAVE header)")
        if head[:4] == b"RIFX":
            raise self._fail("big-endian WAV (RIFX) is not supported; convert it to an ordinary WAV")
        rf64_data: int | None = None
        fmt: bytes | None = None
        for _ in range(MAX_CHUNKS):
            chunk = fh.read(8)
            if len(chunk) < 8:
                break
            cid, size = chunk[:4], struct.unpack("<I", chunk[4:])[0]
            start = fh.tell()
            if cid == b"ds64":
                ds64 = fh.read(min(size, 28))
                if len(ds64) < 16:
                    raise self._fail("not a readable WAV file (truncated ds64 chunk)")
                rf64_data = struct.unpack("<Q", ds64[8:16])[0]
            elif cid == b"fmt ":
                fmt = fh.read(min(size, 40))
                if len(fmt) < 16:
                    raise self._fail("not a readable WAV file (truncated 'fmt ' chunk)")
            elif cid == b"data":
                if fmt is None:
                    raise self._fail("not a readable WAV file (samples before the 'fmt ' chunk)")
                data_size = rf64_data if (size == 0xFFFFFFFF and rf64_data is not None) else size
                self._layout(fmt)
                self._data_start = start
                held = file_size - start
                if data_size > held:
                    seconds = data_size / self._frame_bytes / self.fs
                    raise self._fail(
                        f"the header claims {_size(data_size)} of samples ({seconds:,.0f} s) but the file holds "
                        f"{_size(max(held, 0))}: truncated or corrupt"
                    )
                self.frames = data_size // self._frame_bytes
                if self.frames == 0:
                    raise self._fail("contains no samples")
                return
            if start + size > file_size:
                break
            fh.seek(start + size + (size & 1))
        if fmt is None:
            raise self._fail("not a readable WAV file (no 'fmt ' chunk)")
        raise self._fail("not a readable WAV file (no 'data' chunk: truncated?)")

    def _layout(self, fmt: bytes) -> None:
        tag, channels, fs, _rate, block_align, bits = struct.unpack("<HHIIHH", fmt[:16])
        if tag == _EXTENSIBLE:
            if len(fmt) < 26:
                raise self._fail("not a readable WAV file (truncated WAVE_FORMAT_EXTENSIBLE header)")
            tag = struct.unpack("<H", fmt[24:26])[0]  # the sub-format GUID starts with the format tag
        if tag not in (_PCM, _FLOAT):
            raise self._fail(f"WAV format tag {tag:#06x} is not supported (PCM or IEEE float only)")
        if not 1 <= channels <= MAX_WAV_CHANNELS:
            raise self._fail(f"has {channels} channels (taken: 1..{MAX_WAV_CHANNELS})")
        if not MIN_WAV_RATE <= fs <= MAX_WAV_RATE:
            raise self._fail(f"sample rate {fs} Hz is outside {MIN_WAV_RATE:,}..{MAX_WAV_RATE:,} Hz")
        ok = (tag == _PCM and bits in (8, 16, 24, 32)) or (tag == _FLOAT and bits in (32, 64))
        if not ok:
            kind = "PCM" if tag == _PCM else "float"
            raise self._fail(f"{bits}-bit {kind} samples are not supported")
        if block_align != channels * bits // 8:
            raise self._fail(
                f"not a readable WAV file ({block_align} bytes per frame for {channels} x {bits}-bit channels)"
            )
        self.fs = float(fs)
        self.channels = int(channels)
        self.sample_format = ("pcm" if tag == _PCM else "float") + str(bits)
        self._bits, self._float = int(bits), tag == _FLOAT
        self._frame_bytes = int(block_align)

    # ------------------------------------------------------------------ samples
    def _decode(self, raw: bytes) -> NDArray[np.float64]:
        n = len(raw) // self._frame_bytes
        if self._bits == 8:
            x = (np.frombuffer(raw, np.uint8).astype(np.float64) - 128.0) / 128.0
        elif self._bits == 24:
            b = np.frombuffer(raw, np.uint8).reshape(-1, 3).astype(np.int32)
            x = ((b[:, 0] << 8) | (b[:, 1] << 16) | (b[:, 2] << 24)).astype(np.float64) / 2.0**31
        else:
            key = (_FLOAT if self._float else _PCM, self._bits)
            x = np.frombuffer(raw, _DTYPES[key]).astype(np.float64)
            if not self._float:
                x /= 2.0 ** (self._bits - 1)
        return x.reshape(n, self.channels)

    def read(self, frames: int) -> NDArray[np.float64]:
        """The next (at most) ``frames`` frames, shape (n, channels), float64 in [-1, 1) for PCM.

        An empty array at the end of the file.

        Raises
        ------
        InputError
            The file became unreadable, or a float sample is NaN or infinite (the message
            gives the time of the first).
        """
        if self._fh is None:
            raise ValueError("the WAV reader is closed")
        n = max(0, min(int(frames), self.frames - self.position))
        try:
            self._fh.seek(self._data_start + self.position * self._frame_bytes)
            raw = self._fh.read(n * self._frame_bytes)
        except OSError as exc:
            raise self._fail(f"cannot read ({exc.strerror or exc})") from None
        if len(raw) < n * self._frame_bytes:
            raise self._fail("ended early while reading (the file shrank?)")
        x = self._decode(raw)
        if self._float:
            self._refuse_non_finite(x)
        self.position += n
        return x

    def close(self) -> None:
        """Close the file. Idempotent."""
        fh, self._fh = self._fh, None
        if fh is not None:
            fh.close()
