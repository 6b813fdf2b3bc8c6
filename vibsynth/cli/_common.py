"""Argument types and helpers shared by the sub-commands (validation at the edge)."""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from vibsynth.cli._numbers import finite_float, integer_in, number_in, positive_seconds, unit_interval
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.formats.basis_file import default_basis, load_basis
from vibsynth.settings.models_preset import NAME_PATTERN, NAME_RULE

__all__ = [
    "finite_float",
    "integer_in",
    "number_in",
    "unit_interval",
    "positive_seconds",
    "sample_rate",
    "file_name_argument",
    "validate_files",
    "add_basis_argument",
    "basis_from_args",
    "Progress",
]

MAX_RATE_HZ = 768_000.0


#: A sample rate in Hz within [2400, 768000] (the bank reaches 1000 Hz).
sample_rate = number_in(MIN_RATE_HZ, MAX_RATE_HZ, unit="Hz")


def file_name_argument(noun: str) -> Callable[[str], str]:
    """An argparse type: the name of a preset, clip... (it becomes a file name: no folders, no dot first)."""

    def parse(text: str) -> str:
        if not re.fullmatch(NAME_PATTERN, text):
            raise argparse.ArgumentTypeError(f"{noun} name {text!r}: must be {NAME_RULE}")
        return text

    return parse


def validate_files(
    paths: Sequence[Path],
    load: Callable[[Path], Any],
    error: type[Exception],
    noun: str,
    describe: Callable[[Any], str],
) -> int:
    """``vibsynth preset|clip validate``: read files as the library does; one line per file; the exit code.

    Parameters
    ----------
    paths : sequence of Path
    load : callable
        Reads one file; raises ``error`` (its message names file:line).
    noun : str
        ``preset``, ``clip``: for the summary line.
    describe : callable
        The loaded item -> the text after ``OK`` (``(brick: intensity 0.750, balance -0.870)``).

    Returns
    -------
    int
        0 when every file is valid, else 1.
    """
    bad = 0
    for path in paths:
        try:
            item = load(path)
        except error as exc:
            bad += 1
            print(f"vibsynth: error: {exc}", file=sys.stderr)
        else:
            print(f"{path}: OK {describe(item)}")
    if bad and len(paths) > 1:
        print(f"{bad} of {len(paths)} {noun} files are invalid", file=sys.stderr)
    return 1 if bad else 0


def add_basis_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--basis", metavar="FILE.yaml", type=Path, help="spectral basis (default: the shipped HaTT basis)"
    )


def basis_from_args(args: argparse.Namespace) -> Basis:
    return load_basis(args.basis) if getattr(args, "basis", None) else default_basis()


class Progress:
    """A one-line progress bar on stderr, shown only on a terminal."""

    def __init__(self, label: str, *, stream=None) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = self.stream.isatty()

    def __call__(self, done: int, total: int, name: str) -> None:
        if not self.enabled:
            return
        width = 30
        filled = int(width * done / max(total, 1))
        self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {done}/{total} {name[:30]:<30}")
        if done >= total:
            self.stream.write("\n")
        self.stream.flush()
