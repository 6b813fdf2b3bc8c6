"""Argument types and helpers shared by the sub-commands (validation at the edge)."""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

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
MAX_SECONDS = 3600.0


def finite_float(text: str) -> float:
    """A finite number (NaN and infinities are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def integer_in(low: int, high: int | None = None, *, what: str = "") -> Callable[[str], int]:
    """An argparse type: an integer within [low, high] (``high=None``: no upper bound)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            span = f"{low}..{high}" if high is not None else f">= {low}"
            raise argparse.ArgumentTypeError(f"{what + ' ' if what else ''}{value} is outside {span}")
        return value

    return parse


def number_in(low: float, high: float, *, unit: str = "", low_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number within [low, high] (``low_open``: (low, high])."""

    def parse(text: str) -> float:
        value = finite_float(text)
        if (value <= low if low_open else value < low) or value > high:
            suffix = f" {unit}" if unit else ""
            raise argparse.ArgumentTypeError(
                f"{value:g}{suffix} is outside {'(' if low_open else '['}{low:g}, {high:g}]{suffix}"
            )
        return value

    return parse


unit_interval = number_in(0.0, 1.0)
unit_interval.__doc__ = "A number in [0, 1] (the intensity knob)."


#: A duration in seconds, > 0 and at most an hour (renders).
positive_seconds = number_in(0.0, MAX_SECONDS, unit="s", low_open=True)
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
