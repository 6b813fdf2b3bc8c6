"""``vibsynth send``: send one OSC message to a running ``vibsynth serve`` (and print its replies).

Encoding, parsing and the socket are :mod:`vibsynth.app.client`'s (python-osc), the same as
:class:`vibsynth.Client`. After the message, ``send`` asks ``/ping`` with a random token on
the same socket: the server handles packets in order, so its ``/pong`` tells that the
message was handled and that every error reply about it has already arrived.
"""

from __future__ import annotations

import argparse
import math
import random
import re
import sys
import time
from collections.abc import Sequence

from vibsynth.app.client import (
    IMMEDIATELY,
    Client,
    Reply,
    encode_bundle,
    encode_message,
    format_reply,
)
from vibsynth.cli._server import server_address
from vibsynth.errors import NoReplyError, ParameterError

ORDER = 6

HELP = """\
Send one OSC message over UDP, e.g.
  vibsynth send /vibsynth/intensity 0.5
  vibsynth send /vibsynth/ch/2/texture 0.4 -1
  vibsynth send /vibsynth/source/1/pos 0.02 0.1     (a touch source, with a layout: docs/vr.md)
  vibsynth send /vibsynth/status --wait-reply 1
  vibsynth send /vibsynth/preset 3 --types s        (force types: the name "3" as a string)
  vibsynth send /vibsynth/intensity 0.8 --delay 2   (bundle timetagged 2 s ahead)
Argument types are inferred: integer -> i, other number -> f, anything else -> s.
The exit code is 1 when the server refuses the message (its error is printed). With
--wait-reply, replies are printed as 'ADDRESS TYPES ARGS...' (oscdump style), and the exit
code is also 1 when no server answers within SECONDS. See docs/osc.md for the address space.
"""

_INT = re.compile(r"[+-]?\d+\Z")
_QUIET_S = 0.05
#: Without --wait-reply, how long to wait for the server to confirm (it answers in about a millisecond).
CONFIRM_S = 0.5
_CHANNEL = re.compile(r"/(?:ch|source)/[^/]*\Z")


def infer(text: str) -> tuple[object, str]:
    """An argument's value and type tag from its text: int -> i, float -> f, else s."""
    if _INT.match(text) and -(2**31) <= int(text) < 2**31:
        return int(text), "i"
    try:
        return float(text), "f"
    except ValueError:
        return text, "s"


def convert(values: Sequence[str], types: str | None) -> tuple[list[object], str]:
    """Arguments as values and their type tags (``types`` forces them).

    Raises
    ------
    ParameterError
        If ``types`` does not fit the arguments.
    """
    if types is None:
        pairs = [infer(v) for v in values]
        return [p[0] for p in pairs], "".join(p[1] for p in pairs)
    types = types.lstrip(",")
    data_tags = [t for t in types if t not in "TFNI"]
    if len(data_tags) != len(values):
        raise ParameterError(f"--types {types!r} needs {len(data_tags)} value(s), got {len(values)}")
    out: list[object] = []
    for tag, text in zip(data_tags, values):
        try:
            if tag in "ih":
                out.append(int(text, 0))
            elif tag in "fd":
                out.append(float(text))
            elif tag in "sSc":
                out.append(text)
            elif tag == "b":
                out.append(bytes.fromhex(text))
            else:
                raise ParameterError(f"type tag {tag!r} is not supported by vibsynth send")
        except ValueError:
            raise ParameterError(f"{text!r} is not a valid OSC {tag!r} argument") from None
    return out, types


def format_message(msg: Reply) -> str:
    """``/address types arg...`` (strings quoted only when they contain spaces)."""
    return format_reply(msg)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "send",
        help="send an OSC message to a running server (for tests and scripts)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("address", metavar="ADDRESS", help="OSC address, e.g. /vibsynth/intensity")
    p.add_argument("args", nargs="*", metavar="ARG", help="arguments (types inferred unless --types)")
    p.add_argument("--host", default=None, help="server host (default: osc.host from the config, 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="server UDP port (default: osc.port, 9570)")
    p.add_argument("--types", default=None, metavar="TAGS", help="force type tags, e.g. 'fs' or ',fs'")
    p.add_argument(
        "--delay",
        type=float,
        default=None,
        metavar="S",
        help="send inside a bundle timetagged S seconds from now (0 = immediate bundle)",
    )
    p.add_argument(
        "--wait-reply", type=float, default=0.0, metavar="SECONDS", help="wait up to SECONDS for replies and print them"
    )
    p.add_argument(
        "--from-port",
        type=int,
        default=0,
        metavar="PORT",
        help="local UDP port to send from (replies come back to it; default: any)",
    )
    p.set_defaults(func=run)


def prefix_of(address: str) -> str:
    """The server prefix an address was sent under: ``/vibsynth/ch/2/intensity`` (or ``/vibsynth/source/1/pos``)
    -> ``/vibsynth``."""
    head = address.rstrip("/").rsplit("/", 1)[0]
    return _CHANNEL.sub("", head)


def exchange(client: Client, data: bytes, wait_s: float, confirm_s: float = CONFIRM_S) -> tuple[list[Reply], bool]:
    """Send ``data`` and a ``/ping`` barrier; return ``(replies, answered)``.

    ``replies`` are the server's answers to ``data`` (the barrier's own are left out);
    ``answered`` tells whether the server answered at all. With ``wait_s`` = 0 only until
    the barrier's answer (at most ``confirm_s``); otherwise up to ``wait_s`` seconds,
    stopping 50 ms after the last reply once the barrier was answered.
    """
    token = random.randrange(1, 2**31)
    ping = f"{client.prefix}/ping"
    client.send_packet(data)
    client.send_packet(encode_message(ping, (token, "vibsynth send"), "is"))
    replies: list[Reply] = []
    answered = False
    deadline = time.monotonic() + (wait_s if wait_s > 0 else confirm_s)
    last = -math.inf  # arrival of the last reply to the message
    while True:
        now = time.monotonic()
        remaining = deadline - now
        if answered and (wait_s <= 0 or replies):
            remaining = min(remaining, last + _QUIET_S - now if wait_s > 0 else 0.0)
        if remaining <= 0:
            return replies, answered
        for reply in client.receive(remaining):
            answered = True
            if reply.address == f"{client.prefix}/pong" and reply.args == (token, "vibsynth send"):
                continue
            if _is_error(reply) and reply.args[0] == ping:
                continue  # a server under another prefix: it answered, about our ping
            replies.append(reply)
            last = time.monotonic()


def _is_error(reply: Reply) -> bool:
    """An error reply (``PREFIX/error s address s message``; the server's prefix may differ from the address')."""
    return reply.address.endswith("/error") and len(reply.args) == 2 and all(isinstance(a, str) for a in reply.args)


def run(args: argparse.Namespace) -> int:
    if not args.address.startswith("/"):
        raise ParameterError(f"OSC addresses start with '/', got {args.address!r}")
    wait = args.wait_reply
    if not math.isfinite(wait) or wait < 0:
        raise ParameterError(f"--wait-reply must be a finite number of seconds >= 0, got {wait:g}")
    if not 0 <= args.from_port <= 65535:
        raise ParameterError(f"--from-port {args.from_port} is outside [0, 65535] (0 = any)")
    values, types = convert(args.args, args.types)
    data = encode_message(args.address, values, types)
    if args.delay is not None:
        if not math.isfinite(args.delay):
            raise ParameterError("--delay must be finite")
        data = encode_bundle(IMMEDIATELY if args.delay == 0 else time.time() + args.delay, [data])
    host, port = server_address(args)
    with Client(host, port, prefix=prefix_of(args.address), local_port=args.from_port) as client:
        try:
            replies, answered = exchange(client, data, wait)
        except OSError as exc:
            raise ParameterError(f"cannot send to {host}:{port}: {exc.strerror or exc}") from None
    errors = [r for r in replies if _is_error(r)]
    if wait > 0:
        for msg in replies:
            print(format_message(msg))
        if not answered:
            print(f"vibsynth: error: {NoReplyError(host, port, wait)}", file=sys.stderr)
            return 1
        return 1 if errors else 0
    for error in errors:
        print(f"vibsynth: error: {error.args[0]}: {error.args[1]}", file=sys.stderr)
    return 1 if errors else 0
