"""Tables of the sub-commands, as a readable table, JSON or CSV (``--format``).

Names are never cut where they differ: a table shows whole names when they fit the terminal
(always when the output is a pipe or a file), and otherwise elides the *middle* of a long
name, keeping its start and its distinguishing end (``…/scans/brick-2.wav``).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import shutil
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TextIO

__all__ = ["Column", "FORMATS", "add_format_argument", "output_format", "format_table", "emit", "elide_middle"]

FORMATS = ("table", "json", "csv")
#: Narrowest a name column gets when the terminal is too narrow for whole names.
MIN_NAME_WIDTH = 16


@dataclass(frozen=True)
class Column:
    """One column of a table.

    Parameters
    ----------
    key : str
        Key of the value in each row (also the JSON key and the CSV header).
    head : str
        Heading in the table.
    fmt : callable, optional
        Value -> text for the table (JSON and CSV get the raw value); default ``str``.
    name : bool
        A name column (file, preset): left-aligned, shown whole, elided in the middle only
        when the terminal is too narrow.
    """

    key: str
    head: str
    fmt: Callable[[Any], str] = str
    name: bool = False


def add_format_argument(parser: argparse.ArgumentParser, *, json_alias: bool = True) -> None:
    """Add ``--format table|json|csv`` (and ``--json``, the same as ``--format json``)."""
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default=None,
        help="output: a table for people (default), JSON or CSV for programs",
    )
    if json_alias:
        parser.add_argument("--json", action="store_true", help="same as --format json")


def output_format(args: argparse.Namespace) -> str:
    """The format asked for on the command line (``--json`` is ``--format json``)."""
    chosen = getattr(args, "format", None)
    if getattr(args, "json", False):
        if chosen not in (None, "json"):
            raise argparse.ArgumentTypeError(f"--json and --format {chosen} disagree; give one")
        return "json"
    return chosen or "table"


def elide_middle(text: str, width: int) -> str:
    """``text`` in at most ``width`` characters, the middle replaced by ``…`` (the end is kept longer)."""
    if len(text) <= width:
        return text
    if width <= 1:
        return text[-width:] if width > 0 else ""
    head = (width - 1) // 3
    tail = width - 1 - head
    return text[:head] + "…" + text[len(text) - tail :]


def _terminal_width(stream: TextIO) -> int | None:
    """Columns of the terminal the stream shows on, or None for a pipe or a file (no limit)."""
    try:
        if not stream.isatty():
            return None
    except (AttributeError, ValueError):
        return None
    return shutil.get_terminal_size((100, 24)).columns


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[Column], *, width: int | None = None) -> str:
    """The rows as aligned text; name columns are elided in the middle only to fit ``width``.

    Parameters
    ----------
    rows : sequence of mappings
        One mapping per row, with a value for each column's key.
    columns : sequence of Column
    width : int or None
        Characters available per line (None: unlimited).
    """
    cells = [[col.fmt(row[col.key]) for col in columns] for row in rows]
    widths = [max([len(col.head)] + [len(r[i]) for r in cells]) for i, col in enumerate(columns)]
    if width is not None:
        excess = sum(widths) + len(widths) - 1 - width
        names = [i for i, col in enumerate(columns) if col.name]
        for i in names:
            if excess <= 0:
                break
            cut = min(excess, widths[i] - max(MIN_NAME_WIDTH, len(columns[i].head)))
            if cut > 0:
                widths[i] -= cut
                excess -= cut
        for r in cells:
            for i in names:
                r[i] = elide_middle(r[i], widths[i])

    def line(values: Sequence[str]) -> str:
        parts = [f"{v:<{widths[i]}}" if columns[i].name else f"{v:>{widths[i]}}" for i, v in enumerate(values)]
        return " ".join(parts).rstrip()

    return "\n".join([line([c.head for c in columns])] + [line(r) for r in cells])


def _plain(value: Any) -> Any:
    """JSON/CSV form of a value (numpy scalars and arrays become Python numbers and lists)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def emit(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[Column],
    fmt: str,
    *,
    stream: TextIO | None = None,
    json_rows: Sequence[Mapping[str, Any]] | None = None,
) -> None:
    """Print rows as a table, JSON (a list of objects) or CSV (a header line, then one line per row).

    ``json_rows`` replaces the rows in JSON output when it carries more than the table
    (e.g. every score and band level).
    """
    out = stream if stream is not None else sys.stdout
    if fmt == "json":
        data = json_rows if json_rows is not None else [{c.key: _plain(r[c.key]) for c in columns} for r in rows]
        out.write(json.dumps([{k: _plain(v) for k, v in r.items()} for r in data], indent=2) + "\n")
    elif fmt == "csv":
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow([c.key for c in columns])
        for r in rows:
            writer.writerow([_plain(r[c.key]) for c in columns])
        out.write(buffer.getvalue())
    else:
        out.write(format_table(rows, columns, width=_terminal_width(out)) + "\n")
