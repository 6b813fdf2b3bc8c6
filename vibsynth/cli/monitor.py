"""``vibsynth monitor``: print what a running server receives, as it sees it (like oscdump/aseqdump)."""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import sys
import time
from typing import Any

from vibsynth.cli._numbers import integer_in, positive_seconds
from vibsynth.cli._server import add_server_arguments, server_address

ORDER = 8

HELP = """\
Subscribe to a running `vibsynth serve` (OSC /vibsynth/monitor) and print, one line each,
what it receives and how it takes it:
  osc       an OSC message the handler took, as sent, with its sender (like oscdump)
  osc-fast  one the compiled fast path took straight to the engine (shown within 20 ms)
  midi      a MIDI message, with its port
  error     an error the server answered (to whom, and why)
Runs until Ctrl-C, --seconds or --count. The subscription is renewed every 10 s and ends
when this command ends. Over UDP this works from the server's own machine.
"""

RENEW_S = 10.0


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "monitor",
        help="print incoming OSC and MIDI as the server sees them",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_server_arguments(p)
    p.add_argument("--seconds", type=positive_seconds, default=None, metavar="S", help="stop after S seconds")
    p.add_argument("--count", type=integer_in(1, what="--count"), default=None, metavar="N", help="stop after N events")
    p.add_argument("--format", choices=("text", "json"), default="text", help="text lines (default) or JSON lines")
    p.set_defaults(func=run)


def format_event(when: float, source: str, text: str) -> str:
    """``12:00:01.234 osc      /vibsynth/intensity f 0.5  (udp 127.0.0.1:50000)``."""
    clock = _dt.datetime.fromtimestamp(when).strftime("%H:%M:%S.%f")[:-3]
    return f"{clock} {source:<8} {text}"


def run(args: argparse.Namespace) -> int:
    from vibsynth.app.client import Client, Reply

    host, port = server_address(args)
    prefix = "/vibsynth"
    event_address, done_address = f"{prefix}/monitor.event", f"{prefix}/done"
    shown = 0
    end = None if args.seconds is None else time.monotonic() + args.seconds

    def is_done(reply: Reply) -> bool:
        return reply.address == done_address and list(reply.args[:1]) == [f"{prefix}/monitor"]

    with Client(host, port, timeout=args.timeout) as client:
        client.request(f"{prefix}/monitor", 1, types="i", match=is_done)
        print(f"monitoring {host}:{port} (Ctrl-C to stop)", file=sys.stderr)
        renew_at = time.monotonic() + RENEW_S
        try:
            while end is None or time.monotonic() < end:
                now = time.monotonic()
                if now >= renew_at:
                    client.send(f"{prefix}/monitor", 1, types="i")
                    renew_at = now + RENEW_S
                wait = min(renew_at - now, 0.5 if end is None else max(0.0, end - now))
                for reply in client.receive(timeout=max(wait, 0.0)):
                    if reply.address != event_address or len(reply.args) != 3:
                        continue
                    when, source, text = reply.args
                    if args.format == "json":
                        record: dict[str, Any] = {"time": when, "source": source, "text": text}
                        print(json.dumps(record), flush=True)
                    else:
                        print(format_event(float(when), str(source), str(text)), flush=True)
                    shown += 1
                    if args.count is not None and shown >= args.count:
                        return 0
        except KeyboardInterrupt:
            pass
        finally:
            try:
                client.send(f"{prefix}/monitor", 0, types="i")
            except Exception:  # noqa: BLE001 - leaving anyway; the server's lease ends it
                pass
    return 0
