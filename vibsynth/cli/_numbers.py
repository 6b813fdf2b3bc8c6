"""Argument types for numbers (validation at the edge), in a module that imports only the standard
library: the commands a script calls in a loop (``send``, ``status``) start without numpy or pydantic."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["finite_float", "integer_in", "number_in", "unit_interval", "positive_seconds", "MAX_SECONDS"]

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
