"""Argument types and helpers shared by the sub-commands (validation at the edge)."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.io import default_basis, load_basis

__all__ = [
    "finite_float",
    "unit_interval",
    "positive_seconds",
    "sample_rate",
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


def unit_interval(text: str) -> float:
    """A number in [0, 1] (the intensity knob)."""
    value = finite_float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{value:g} is outside [0, 1]")
    return value


def positive_seconds(text: str) -> float:
    """A duration in seconds, > 0 and at most an hour."""
    value = finite_float(text)
    if not 0.0 < value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"{value:g} s is outside (0, {MAX_SECONDS:g}] s")
    return value


def sample_rate(text: str) -> float:
    """A sample rate in Hz within [2400, 768000]."""
    value = finite_float(text)
    if not MIN_RATE_HZ <= value <= MAX_RATE_HZ:
        raise argparse.ArgumentTypeError(
            f"{value:g} Hz is outside [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz (the bank reaches 1000 Hz)"
        )
    return value


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
