"""The ``vibsynth`` command line.

Sub-commands live in their own modules in this package; each defines
``ORDER`` (an int for --help ordering) and ``register(subparsers)``, which adds a
parser whose ``func`` default takes the parsed arguments and returns an exit code.
Modules are discovered automatically, so adding a command touches no shared file.

Errors raised on purpose (:class:`~vibsynth.errors.VibsynthError`) print one line
``vibsynth: error: ...`` and exit with code 2; nothing prints a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence

from vibsynth import __version__
from vibsynth.errors import VibsynthError

__all__ = ["main", "build_parser", "EXIT_USAGE"]

EXIT_USAGE = 2

DESCRIPTION = """\
vibsynth: haptic texture synthesis from two perceptual knobs.

Units used everywhere:
  intensity  knob 0..1; 0 = silent; (0, 1] spans --range-db (default 40 dB) below
             the ceiling band level (default -40 dB re unit RMS) of the 80-200 Hz
             Butterworth band (the paper's intensity model).
  balance    high/low frequency balance, dimensionless: 0 = the basis' mean
             spectrum M, +1/-1 = the 98th/2nd percentile of t1 over the basis'
             database, positive = brighter (more high-frequency energy).
             Values beyond +-1 are legal.
  t1         the raw first PCA score (science output), dB units of the spectrum.
"""


def _subcommand_modules() -> list:
    modules = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            modules.append(module)
    return sorted(modules, key=lambda m: (getattr(m, "ORDER", 100), m.__name__))


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every discovered sub-command."""
    parser = argparse.ArgumentParser(
        prog="vibsynth", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"vibsynth {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _subcommand_modules():
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vibsynth`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING if args.verbose == 0 else logging.INFO if args.verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="vibsynth: %(levelname)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(args.func(args) or 0)
    except VibsynthError as exc:
        print(f"vibsynth: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
