"""``vibsynth status``: a running server's output, engine, counters and knobs per channel."""

from __future__ import annotations

import argparse
import json
from typing import Any

from vibsynth.cli._server import add_server_arguments, server_address
from vibsynth.cli._table import FORMATS, Column, emit, format_table

ORDER = 7

HELP = """\
Ask a running `vibsynth serve` for its state (OSC /vibsynth/status) and show it:
the output (device, host API, rate, block; streaming, null or device lost), the engine
(load, underflows, scheduled moves), the control counters, live Follow's input, level and
gate (when it runs) and the last error, then each channel's knobs. --format json prints
every key the server sent (docs/osc.md lists them).
Exit code 1 when no server answers.
"""

CHANNEL_COLUMNS = (
    Column("channel", "channel"),
    Column("intensity", "intensity", lambda v: f"{v:.3f}"),
    Column("balance", "balance", lambda v: f"{v:+.3f}"),
    Column("glide", "glide ms", lambda v: f"{v:.0f}"),
    Column("mute", "mute", lambda v: "muted" if v else "-"),
    Column("preset", "preset", lambda v: v or "-"),
)
#: Shown while live Follow runs: whether each channel follows the input.
FOLLOW_COLUMN = Column("follow", "follow", lambda v: {1: "on", 0: "off"}.get(v, "-"))


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "status",
        help="show a running server's device, state, counters and knobs",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_server_arguments(p)
    p.add_argument("--format", choices=FORMATS, default="table", help="table (default), json or csv (the channels)")
    p.set_defaults(func=run)


def channels_of(status: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per channel from the ``chN.*`` keys of a status reply."""
    rows = []
    n = int(status.get("channels", 0))
    for ch in range(1, n + 1):
        row: dict[str, Any] = {"channel": ch}
        for key in ("intensity", "balance", "glide", "mute", "preset"):
            row[key] = status.get(f"ch{ch}.{key}", "" if key == "preset" else 0)
        if "follow.device" in status:
            row["follow"] = status.get(f"ch{ch}.follow", "")  # absent: no follow route into the channel
        rows.append(row)
    return rows


def _pct(value: object) -> str:
    return f"{100 * float(value):.1f} %" if isinstance(value, (int, float)) and value >= 0 else "?"


def _v(status: dict[str, Any], key: str) -> str:
    """A status value as text; missing or -1 (the engine does not report it) is ``?``."""
    value = status.get(key)
    if value is None or (isinstance(value, (int, float)) and value == -1):
        return "?"
    return f"{value:g}" if isinstance(value, float) else str(value)


def summary(status: dict[str, Any], where: str) -> str:
    """The readable part above the channel table."""
    s = status
    lines = [f"vibsynth {s.get('version', '?')} at {where}, up {float(s.get('uptime', 0)):.0f} s"]
    state = s.get("output", "") or "?"
    reason = f" ({s['output_reason']})" if s.get("output_reason") else ""
    lines.append(f"  output    {state}{reason}")
    if s.get("device"):
        lines.append(f"            {s['device']}")
    lines.append(
        f"  engine    {_v(s, 'rate')} Hz, block {_v(s, 'block_size')}, load {_pct(s.get('load'))} "
        f"(peak {_pct(s.get('load_peak'))}), underflows {_v(s, 'underflows')}, "
        f"scheduled {_v(s, 'scheduled_pending')}, late {_v(s, 'late_commands')}"
    )
    lines.append(
        f"  control   messages {_v(s, 'messages')}, fast path {_v(s, 'fast_path')}, "
        f"errors {_v(s, 'errors')}, malformed {_v(s, 'malformed')}, denied {_v(s, 'denied')}, "
        f"subscribers {_v(s, 'subscribers')}"
    )
    if "follow.device" in s:
        gate = "open" if s.get("follow.gate") else "closed"
        lines.append(
            f"  follow    {s['follow.device']}, level {_v(s, 'follow.level_db')} dB, gate {gate} "
            f"(at {_v(s, 'follow.gate_db')} dB), gain {_v(s, 'follow.gain')} dB, focus {s.get('follow.focus', '?')}"
        )
    if s.get("last_error"):
        lines.append(f"  last error {float(s.get('last_error_age', 0)):.0f} s ago: {s['last_error']}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from vibsynth.app.client import Client

    host, port = server_address(args)
    with Client(host, port, timeout=args.timeout) as client:
        status = client.status()
    rows = channels_of(status)
    columns = CHANNEL_COLUMNS + ((FOLLOW_COLUMN,) if "follow.device" in status else ())
    if args.format == "json":
        print(json.dumps(status, indent=2))
    elif args.format == "csv":
        emit(rows, columns, "csv")
    else:
        print(summary(status, f"{host}:{port}"))
        print()
        print(format_table(rows, columns))
    return 0
