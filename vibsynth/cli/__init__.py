"""The ``vibsynth`` command line.

Sub-commands live in their own modules in this package; each defines
``ORDER`` (an int for --help ordering) and ``register(subparsers)``, which adds a
parser whose ``func`` default takes the parsed arguments and returns an exit code.
Modules are discovered automatically, so adding a command touches no shared file.

Every error prints one line ``vibsynth: error: ...`` on stderr, never a traceback:

* a bad argument (argparse, or :class:`~vibsynth.errors.ParameterError` raised while checking
  arguments) exits with :data:`EXIT_USAGE` (2);
* anything that goes wrong at run time (a bad or missing file, a device, a refused write, an
  unexpected failure) exits with :data:`EXIT_RUNTIME` (1). An unexpected exception says so and
  how to get the traceback (``-vv``);
* a closed pipe (``vibsynth ... | head``, the reader gone before, during or after the first
  write, the last write being the flush at exit) ends the command quietly, nothing on stderr,
  with :data:`EXIT_PIPE` (141 = 128 + SIGPIPE): what a shell reports for a C program its
  reader left (``yes | head``), so a script can tell the output was not all read.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, NoReturn

from vibsynth import __version__
from vibsynth.errors import ConfigError, ParameterError, VibsynthError

if TYPE_CHECKING:
    from _typeshed import SupportsWrite

__all__ = ["main", "build_parser", "EXIT_USAGE", "EXIT_RUNTIME", "EXIT_PIPE"]

EXIT_USAGE = 2
EXIT_RUNTIME = 1
EXIT_PIPE = 141  # 128 + SIGPIPE (13 on every POSIX system; written out for Windows, which has none)

log = logging.getLogger("vibsynth")

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


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``vibsynth: error: <what> (see vibsynth render --help)``."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"vibsynth: error: {message} (see {self.prog} --help)\n")

    def _print_message(self, message: str, file: SupportsWrite[str] | None = None) -> None:
        # argparse drops an OSError here: a --help whose reader left would exit 0, as if read
        if message:
            (file or sys.stdout).write(message)


def build_parser(modules: Sequence | None = None) -> argparse.ArgumentParser:
    """The argument parser with every discovered sub-command (or only those of ``modules``)."""
    parser = _Parser(prog="vibsynth", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"vibsynth {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _subcommand_modules() if modules is None else modules:
        module.register(subparsers)
    return parser


def _parser_for(argv: Sequence[str]) -> argparse.ArgumentParser:
    """A parser for ``argv``: when its command lives in the module of the same name, that module's only.

    Importing every command's module (numpy, scipy, pydantic, aiohttp...) is most of a start; ``vibsynth
    send`` in a script loop should not pay for ``serve``. Anything else (top-level ``--help``, a typo, a
    command whose module is named otherwise) gets the full parser, so its help and errors are unchanged.
    """
    command = next((a for a in argv if not a.startswith("-")), None)
    if command and command.isidentifier() and not command.startswith("_"):
        try:
            module = importlib.import_module(f"{__name__}.{command}")
        except ImportError:
            module = None
        if module is not None and hasattr(module, "register"):
            parser = build_parser([module])
            choices = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
            if command in choices:
                return parser
    return build_parser()


class _LineFormatter(logging.Formatter):
    """``vibsynth: warning: ...``: log lines look like the CLI's own messages."""

    def format(self, record: logging.LogRecord) -> str:
        return f"vibsynth: {record.levelname.lower()}: {record.getMessage()}"


def _error(message: str) -> None:
    print(f"vibsynth: error: {message}", file=sys.stderr)


def _drop_stdout() -> None:
    """stdout cannot be written (its reader left, a full disk): what it still holds goes to /dev/null.

    Python flushes stdout again when it exits; without this, that flush fails once more and
    prints ``Exception ignored in: <_io.TextIOWrapper name='<stdout>'>``.
    """
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _flush_stdout(*, failed_already: bool) -> int | None:
    """Write out what stdout holds now, not at exit: None when done, else the exit code.

    A reader that left is :data:`EXIT_PIPE`, quietly; another failure (a full disk) is
    :data:`EXIT_RUNTIME` with one line, unless the command ``failed_already`` (it said why).
    """
    try:
        if sys.stdout is not None:
            sys.stdout.flush()
        return None
    except BrokenPipeError:
        _drop_stdout()
        return EXIT_PIPE
    except OSError as exc:
        _drop_stdout()
        if not failed_already:
            _error(f"standard output: {exc.strerror or exc}")
        return EXIT_RUNTIME
    except ValueError:  # stdout closed by the command: nothing left to write
        return None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``vibsynth`` console script; returns the exit code.

    argparse's own exits (``--help``, ``--version``, a usage error) raise :class:`SystemExit`
    as usual. Whatever was printed is flushed here, so a reader that left (a closed pipe) gives
    :data:`EXIT_PIPE` (as a C program killed by SIGPIPE, whatever it would have returned) and no
    ``Exception ignored ... BrokenPipeError`` when Python exits. A command that failed and
    could not write its output either keeps its own exit code.
    """
    try:
        code = _run(argv)
    except SystemExit as exc:
        failed = _flush_stdout(failed_already=bool(exc.code))
        if failed == EXIT_PIPE or (failed is not None and not exc.code):
            raise SystemExit(failed) from None
        raise
    except BrokenPipeError:  # a write while the command ran
        _drop_stdout()
        return EXIT_PIPE
    failed = _flush_stdout(failed_already=code != 0)
    return failed if failed == EXIT_PIPE or (failed is not None and code == 0) else code


def _run(argv: Sequence[str] | None) -> int:
    """Parse and run one command: its exit code, every error as one line (a closed stdout is the caller's)."""
    if list(sys.argv[1:] if argv is None else argv) == ["--version"]:
        # answered before the sub-commands are imported (numpy, scipy, aiohttp...: most of a start)
        print(f"vibsynth {__version__}")
        return 0
    parser = _parser_for(list(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(argv)
    level = logging.WARNING if args.verbose == 0 else logging.INFO if args.verbose == 1 else logging.DEBUG
    handler = logging.StreamHandler()
    handler.setFormatter(_LineFormatter())
    logging.basicConfig(level=level, handlers=[handler])
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # stdout's reader left: main ends quietly (an OSError, but not an error to report)
        raise
    except ParameterError as exc:
        _error(str(exc))
        return EXIT_USAGE
    except argparse.ArgumentTypeError as exc:  # an argument type checked after parsing
        _error(str(exc))
        return EXIT_USAGE
    except ConfigError as exc:  # a value given with --set or a flag is a usage error; a file's, a runtime one
        _error(str(exc))
        return EXIT_USAGE if str(exc).startswith("command line:") else EXIT_RUNTIME
    except VibsynthError as exc:
        _error(str(exc))
        return EXIT_RUNTIME
    except KeyboardInterrupt:
        return 130
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        _error(f"{where}{exc.strerror or exc}")
        return EXIT_RUNTIME
    except Exception as exc:  # the last line of defence: one line, the traceback only on request
        log.debug("unexpected failure", exc_info=True)
        _error(f"unexpected {type(exc).__name__}: {exc} (a bug: please report it; -vv shows the traceback)")
        return EXIT_RUNTIME


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
