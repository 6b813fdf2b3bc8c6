"""``vibsynth send``: send one OSC message to a running ``vibsynth serve`` (and print its replies)."""

from __future__ import annotations

import argparse
import math
import re
import select
import socket
import sys
import time
from collections.abc import Sequence

from vibsynth.control.osc.codec import (
    IMMEDIATE,
    Bundle,
    MalformedPacket,
    Message,
    decode_packet,
    encode_bundle,
    encode_message,
    iter_messages,
    unix_to_ntp,
)
from vibsynth.errors import ParameterError

ORDER = 6

HELP = """\
Send one OSC message over UDP, e.g.
  vibsynth send /vibsynth/intensity 0.5
  vibsynth send /vibsynth/ch/2/texture 0.4 -1
  vibsynth send /vibsynth/status --wait-reply 1
  vibsynth send /vibsynth/preset 3 --types s        (force types: the name "3" as a string)
  vibsynth send /vibsynth/intensity 0.8 --delay 2   (bundle timetagged 2 s ahead)
Argument types are inferred: integer -> i, other number -> f, anything else -> s.
With --wait-reply, replies are printed as 'ADDRESS TYPES ARGS...' (oscdump style); the exit code is 1
when an error reply (/.../error) arrived. See docs/osc.md for the address space.
"""

_INT = re.compile(r"[+-]?\d+\Z")
_QUIET_S = 0.05


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


def format_message(msg: Message) -> str:
    """``/address types arg...`` (strings quoted only when they contain spaces)."""
    parts = [msg.address, msg.types or "-"]
    for arg in msg.args:
        if isinstance(arg, float):
            parts.append(repr(arg) if math.isfinite(arg) else str(arg))
        elif isinstance(arg, str):
            parts.append(repr(arg) if (" " in arg or not arg) else arg)
        else:
            parts.append(str(arg))
    return " ".join(parts)


def register(subparsers: argparse._SubParsersAction) -> None:
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


def _defaults(args: argparse.Namespace) -> tuple[str, int]:
    host, port = args.host, args.port
    if host is None or port is None:
        try:
            from vibsynth.settings.config import load_config

            section = load_config().data.get("osc", {})
        except Exception:  # noqa: BLE001 - the client must work even with a broken config
            section = {}
        host = host or section.get("host") or "127.0.0.1"
        port = port if port is not None else int(section.get("port") or 9570)
    if host in ("0.0.0.0", "::"):
        host = "127.0.0.1"
    if not 1 <= port <= 65535:
        raise ParameterError(f"--port {port} is outside [1, 65535]")
    return host, port


def receive_replies(sock: socket.socket, wait_s: float) -> list[Message]:
    """Replies arriving within ``wait_s`` (stops 50 ms after the last one)."""
    replies: list[Message] = []
    deadline = time.monotonic() + wait_s
    while True:
        remaining = deadline - time.monotonic()
        if replies:
            remaining = min(remaining, _QUIET_S)
        if remaining <= 0:
            return replies
        ready, _, _ = select.select([sock], [], [], remaining)
        if not ready:
            return replies
        data = sock.recv(65536)
        try:
            packet = decode_packet(data)
        except MalformedPacket as exc:
            print(f"vibsynth: malformed reply ({exc})", file=sys.stderr)
            continue
        if isinstance(packet, Bundle):
            replies.extend(m for m, _ in iter_messages(packet))
        else:
            replies.append(packet)


def run(args: argparse.Namespace) -> int:
    if not args.address.startswith("/"):
        raise ParameterError(f"OSC addresses start with '/', got {args.address!r}")
    values, types = convert(args.args, args.types)
    data = encode_message(args.address, values, types)
    if args.delay is not None:
        if not math.isfinite(args.delay):
            raise ParameterError("--delay must be finite")
        timetag = IMMEDIATE if args.delay == 0 else unix_to_ntp(time.time() + args.delay)
        data = encode_bundle(timetag, [data])
    host, port = _defaults(args)
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        sock.bind(("::" if family == socket.AF_INET6 else "0.0.0.0", args.from_port))
        try:
            sock.sendto(data, (host, port))
        except OSError as exc:
            raise ParameterError(f"cannot send to {host}:{port}: {exc.strerror or exc}") from None
        if args.wait_reply <= 0:
            return 0
        replies = receive_replies(sock, args.wait_reply)
    for msg in replies:
        print(format_message(msg))
    if not replies:
        print(f"vibsynth: no reply within {args.wait_reply:g} s", file=sys.stderr)
    return 1 if any(m.address.endswith("/error") for m in replies) else 0
