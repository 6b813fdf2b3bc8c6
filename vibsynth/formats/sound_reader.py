"""Any sound file read block by block: WAV by vibsynth's own reader, the rest through libsndfile.

Sound libraries hold more than WAV: games ship Ogg Vorbis, sample packs FLAC, desktops Ogg
(``.oga``), podcasts MP3. :func:`open_sound` sniffs the file's first bytes: a RIFF/RF64 WAV goes
to :class:`~vibsynth.formats.wav_reader.WavReader` (every PCM and float layout, RF64 over
4 GiB, its own header checks); anything else to :class:`SoundFileReader`, which decodes FLAC,
Ogg Vorbis/Opus, MP3, AIFF, CAF, W64 and the other formats of libsndfile (the ``soundfile``
package bundles it). Both hand out float64 frames ``(n, channels)`` in blocks, so memory stays
at one block whatever the length, and both refuse a bad file with one
:class:`~vibsynth.errors.InputError` line naming it (channel count and rate bounds are the WAV
reader's: :data:`~vibsynth.formats.wav_reader.MAX_WAV_CHANNELS`...).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError
from vibsynth.formats.wav_reader import MAX_WAV_CHANNELS, MAX_WAV_RATE, MIN_WAV_RATE, BlockReader, WavReader

__all__ = ["SoundFileReader", "open_sound", "READABLE", "SOUND_SUFFIXES"]

#: What :func:`open_sound` reads, for messages and docs.
READABLE = "WAV, FLAC, Ogg Vorbis/Opus (.ogg, .oga, .opus), MP3, AIFF, CAF, W64"

#: File name endings taken as sound files (a folder conversion picks these; a live ``--follow`` path too).
SOUND_SUFFIXES = (".wav", ".wave", ".flac", ".ogg", ".oga", ".opus", ".mp3", ".aif", ".aiff", ".aifc", ".caf", ".w64")

_WAV_MAGIC = (b"RIFF", b"RF64", b"RIFX")


def open_sound(path: str | os.PathLike[str]) -> BlockReader:
    """A reader for the sound file at ``path``: WAV by its header, anything else through libsndfile.

    Raises
    ------
    InputError
        Missing, unreadable or empty file, a format neither reader decodes, channels or rate
        out of bounds (one line naming the file).
    """
    where = Path(path)
    if where.is_dir():
        raise InputError(f"{where}: is a folder, expected a sound file ({READABLE})")
    try:
        with open(where, "rb") as fh:
            head = fh.read(12)
    except OSError as exc:
        raise InputError(f"{where}: cannot read ({exc.strerror or exc})") from None
    if head[:4] in _WAV_MAGIC and head[8:12] == b"WAVE":
        return WavReader(where)
    return SoundFileReader(where)


class SoundFileReader(BlockReader):
    """A sound file decoded by libsndfile, read in blocks of frames.

    Parameters
    ----------
    path : path-like

    Attributes
    ----------
    path : pathlib.Path
    fs : float
    channels : int
    frames : int
        Frames the file's header announces (a compressed stream that ends earlier ends there).
    sample_format : str
        libsndfile's format and encoding, e.g. ``"OGG/VORBIS"``, ``"FLAC/PCM_24"``.
    position : int
        Frames read so far.

    Raises
    ------
    InputError
        The ``soundfile`` package or libsndfile missing, a file libsndfile does not decode,
        channels or rate out of bounds, no samples.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            import soundfile
        except (ImportError, OSError) as exc:  # OSError: the package is there, libsndfile is not
            raise self._fail(f"only WAV can be read here: the soundfile package is unusable ({exc})") from None
        try:
            self._file: Any = soundfile.SoundFile(str(self.path))
        except (RuntimeError, TypeError, ValueError, OSError) as exc:  # soundfile.LibsndfileError is a RuntimeError
            why = str(exc).split(": ", 1)[-1] if str(exc) else type(exc).__name__
            raise self._fail(f"not a sound file vibsynth reads ({READABLE}): {why}") from None
        try:
            self._check()
        except BaseException:
            self.close()
            raise
        self.position = 0

    def _check(self) -> None:
        f = self._file
        self.fs = float(f.samplerate)
        self.channels = int(f.channels)
        self.frames = int(f.frames)
        self.sample_format = f"{f.format}/{f.subtype}"
        if not 1 <= self.channels <= MAX_WAV_CHANNELS:
            raise self._fail(f"{self.channels} channels; at most {MAX_WAV_CHANNELS} are taken")
        if not MIN_WAV_RATE <= self.fs <= MAX_WAV_RATE:
            raise self._fail(f"sample rate {self.fs:g} Hz is outside {MIN_WAV_RATE}..{MAX_WAV_RATE} Hz")
        if self.frames <= 0:
            raise self._fail("holds no samples")

    def read(self, frames: int) -> NDArray[np.float64]:
        """The next (at most) ``frames`` frames, shape (n, channels), float64; empty at the end.

        Raises
        ------
        InputError
            The stream cannot be decoded further (a damaged file), or a sample is NaN or
            infinite (the message gives the time of the first).
        """
        if self._file is None:
            raise ValueError("the sound reader is closed")
        n = max(0, min(int(frames), self.frames - self.position))
        if n == 0:
            return np.zeros((0, self.channels))
        try:
            x = self._file.read(n, dtype="float64", always_2d=True)
        except (RuntimeError, ValueError, OSError) as exc:
            raise self._fail(f"cannot decode at {self.position / self.fs:.3f} s ({exc})") from None
        if x.shape[0] < n:  # a stream shorter than its header said: it ends here
            self.frames = self.position + x.shape[0]
        self._refuse_non_finite(x)
        self.position += x.shape[0]
        return np.ascontiguousarray(x)

    def close(self) -> None:
        """Close the file. Idempotent."""
        f, self._file = getattr(self, "_file", None), None
        if f is not None:
            f.close()
