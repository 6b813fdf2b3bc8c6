"""The progress bar of offline renders (``render``, ``render --midi|--follow``, ``decode``, ``clip from-audio``):
tqdm on stderr.

Shown only when both stdout and stderr are a terminal and ``--quiet`` is not given, so a
script, a pipe or a log file never receives bar characters. The renderer calls
``progress(frames_done, frames_total)`` after every block; tqdm redraws at most
:data:`REDRAWS_PER_SECOND` times a second (its ``mininterval``) and always draws the final
100 %. A failed render clears its bar, so the error line stands alone.
"""

from __future__ import annotations

import argparse
import os
import sys
from types import TracebackType
from typing import IO, Any

__all__ = ["RenderProgress", "add_quiet_argument", "REDRAWS_PER_SECOND"]

#: Most redraws of the bar per second.
REDRAWS_PER_SECOND = 10
#: (columns, lines) assumed when the terminal does not say.
DEFAULT_SIZE = (80, 24)


def add_quiet_argument(parser: argparse.ArgumentParser) -> None:
    """``-q/--quiet``: no progress bar and no summary line (warnings and errors still print)."""
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress bar and no summary line (warnings and errors still print); "
        "the bar is shown only on a terminal anyway",
    )


def _size(stream: Any) -> tuple[int, int]:
    """The terminal's (columns, lines); 0 for what it does not say (a new pseudo-terminal says 0 x 0)."""
    try:
        size = os.get_terminal_size(stream.fileno())
    except (AttributeError, ValueError, OSError):
        return 0, 0
    return int(size.columns), int(size.lines)


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or closed
        return False


class RenderProgress:
    """A progress bar for one render, as a ``progress(frames_done, frames_total)`` callback.

    Parameters
    ----------
    label : str
        Shown before the bar ("render", "decode").
    frames : int
        Length of the render (frames).
    fs : float
        Sample rate: the bar counts seconds of output.
    quiet : bool
        Never show the bar.
    stream : file, optional
        Where the bar goes (default ``sys.stderr``).
    enabled : bool, optional
        Force the bar on or off (tests); default: on when ``stream`` and ``sys.stdout``
        are terminals and not ``quiet``.
    unit : {"s", "files"}
        What the bar counts: seconds (``frames / fs``) or whole items (``fs`` 1).

    Notes
    -----
    Use it as a context manager around the render: on success the bar is left at 100 %,
    on an error it is cleared.
    """

    def __init__(
        self,
        label: str,
        frames: int,
        fs: float,
        *,
        quiet: bool = False,
        stream: IO[str] | None = None,
        enabled: bool | None = None,
        unit: str = "s",
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            enabled = not quiet and _is_terminal(self.stream) and _is_terminal(sys.stdout)
        self.enabled = bool(enabled)
        self.frames = int(frames)
        self._bar: Any = None
        if self.enabled:
            from tqdm import tqdm

            class _Bar(tqdm):
                monitor_interval = 0  # no monitor thread: update() is called every block anyway

            columns, lines = _size(self.stream)
            self._bar = _Bar(
                total=self.frames,
                desc=label,
                file=self.stream,
                unit="s",
                unit_scale=1.0 / float(fs),
                mininterval=1.0 / REDRAWS_PER_SECOND,
                ncols=columns or DEFAULT_SIZE[0],
                nrows=lines or DEFAULT_SIZE[1],  # tqdm hides every bar on a terminal that reports 0 lines
                dynamic_ncols=bool(columns and lines),
                bar_format=(
                    "{desc}: {percentage:3.0f}%|{bar}| "
                    + ("{n:.0f}/{total:.0f} files" if unit == "files" else "{n:.1f}/{total:.1f} s")
                    + " [{elapsed}<{remaining}]"
                ),
            )

    def __call__(self, done: int, total: int) -> None:
        """The renderer's callback: ``done`` frames of ``total`` are written.

        A ``total`` other than the bar's (the output of a render counted at another rate than
        its input) is scaled onto it.
        """
        bar = self._bar
        if bar is None:
            return
        if total != self.frames and total > 0:
            done = int(done * self.frames / total)
        if done > bar.n:
            bar.update(done - bar.n)

    def close(self, *, ok: bool = True) -> None:
        """Finish the bar: left on screen when ``ok``, cleared otherwise. Idempotent."""
        bar, self._bar = self._bar, None
        if bar is None:
            return
        if not ok:
            bar.leave = False
        bar.close()

    def __enter__(self) -> RenderProgress:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(ok=exc_type is None)
