"""Lists of recordings on the command line: files, and folders with ``--recursive``."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path

from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import RECORDING_SUFFIXES

__all__ = ["add_recursive_argument", "expand_recordings", "wav_channel", "MAX_FILES"]

#: Most recordings one command takes from folders (a typo'd ``/`` must not walk the disk for minutes).
MAX_FILES = 10_000


def add_recursive_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``-r/--recursive``: folders among the files stand for every recording under them."""
    parser.add_argument(
        "-r",
        "--recursive",
        action="store_true",
        help=f"a FOLDER stands for every recording under it ({', '.join(RECORDING_SUFFIXES)}), sorted",
    )


def expand_recordings(paths: Sequence[str | os.PathLike[str]], *, recursive: bool) -> list[Path]:
    """The recordings named by ``paths``: files as given, folders walked when ``recursive``.

    Raises
    ------
    ParameterError
        A folder without ``recursive`` (a usage error).
    InputError
        A folder with no recordings, a missing path, or more than :data:`MAX_FILES` recordings.
    """
    out: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            if not recursive:
                raise ParameterError(f"{path}: is a folder (add --recursive to take the recordings under it)")
            found = []
            for folder, dirs, files in os.walk(path):
                dirs.sort()
                for name in sorted(files):
                    if Path(name).suffix.lower() in RECORDING_SUFFIXES:
                        found.append(Path(folder) / name)
                        if len(out) + len(found) > MAX_FILES:
                            raise InputError(f"{path}: more than {MAX_FILES:,} recordings; name a smaller folder")
            if not found:
                raise InputError(f"{path}: no recordings ({', '.join(RECORDING_SUFFIXES)}) in this folder")
            out += found
        elif path.exists():
            out.append(path)
        else:
            raise InputError(f"{path}: no such file or folder")
        if len(out) > MAX_FILES:
            raise InputError(f"more than {MAX_FILES:,} recordings")
    return out


def wav_channel(text: str) -> int:
    """An argparse type: a WAV channel as people count it (1 = the first), returned 0-based."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a channel number (1 = the first)") from None
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"channel {value} is outside 1..65535 (1 = the first)")
    return value - 1
