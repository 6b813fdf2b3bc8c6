"""``vibsynth discover``: the OSCQuery services on the network (mDNS ``_oscjson._tcp``), with their OSC addresses."""

from __future__ import annotations

import argparse
import sys

from vibsynth.cli._numbers import number_in
from vibsynth.cli._table import Column, add_format_argument, emit, output_format

ORDER = 8

HELP = """\
Listen for OSCQuery services on the local network (mDNS/zeroconf _oscjson._tcp) for a
while and list each one: its name, its OSC address (from its HOST_INFO) and its OSCQuery
URL (open it in a browser to read the address space as JSON). A vibsynth server
advertises itself when it listens on a network interface (osc.host, discovery.interfaces;
docs/osc.md "Discovery"). Exit code 0 even when none answered.
"""

COLUMNS = (
    Column("name", "name", name=True),
    Column("osc", "OSC"),
    Column("oscquery", "OSCQuery"),
)

_seconds = number_in(0.1, 60.0, unit="s")


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "discover",
        help="list the OSC/OSCQuery services found on the network (mDNS)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--seconds", type=_seconds, default=2.0, metavar="S", help="how long to listen (default 2)")
    p.add_argument(
        "--interface",
        action="append",
        default=None,
        metavar="IP",
        help="browse on this interface address only (repeat for more; default: every interface)",
    )
    add_format_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vibsynth.control.oscquery.discovery import discover

    fmt = output_format(args)
    found = discover(args.seconds, interfaces=args.interface)
    rows = [{"name": f.name, "osc": f.osc, "oscquery": f.oscquery_url} for f in found]
    if not rows and fmt == "table":
        print(f"no OSCQuery services answered in {args.seconds:g} s", file=sys.stderr)
        return 0
    emit(rows, COLUMNS, fmt)
    return 0
