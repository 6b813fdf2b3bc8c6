"""``vibsynth clip play`` and ``vibsynth clip stop`` (a running server plays the clip), and the
playback flags they share with ``vibsynth render --clip``.

``clip play`` sends ``/vibsynth/play`` (or ``/vibsynth/ch/{n}/play``) to a running
``vibsynth serve`` and waits for the server to confirm it was handled (a ``/ping`` barrier,
as ``vibsynth send`` does): an unknown clip or a bad value prints the server's error line and
exits 1; no server answering exits 1 too. The values are checked here first (exit 2).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from vibsynth.app.client import Client, encode_bundle, encode_message
from vibsynth.cli._numbers import integer_in, number_in
from vibsynth.cli._server import add_server_arguments, server_address
from vibsynth.control.clips.timeline import GAIN_MAX, LOOPS_MAX, RATE_MAX, RATE_MIN
from vibsynth.errors import NoReplyError, ParameterError
from vibsynth.settings.models_config import MAX_CHANNELS

__all__ = ["add_clip_play_arguments", "add_clip_play_parsers"]

PLAY_HELP = """\
Play a haptic clip on a running server (vibsynth serve): sends /vibsynth/play (or
/vibsynth/ch/N/play with --channel) and waits until the server has handled it. An unknown
clip or a refused value prints the server's error and exits 1, as does a server that does
not answer; a bad argument exits 2. --at S starts it S seconds from now, at that exact
sample (a timetagged bundle). See docs/clips.md.
"""

#: How long ``--at`` may look ahead (the server's default schedule horizon).
MAX_AT_S = 10.0


def add_clip_play_arguments(parser: argparse.ArgumentParser, *, rate_flag: str = "--clip-rate") -> None:
    """``--gain``, the rate flag and ``--loops`` (defaults: as designed, once)."""
    parser.add_argument(
        "--gain",
        type=number_in(0.0, GAIN_MAX),
        default=1.0,
        metavar="G",
        help=f"scale the clip's intensity, 0..{GAIN_MAX:g} (default 1; the result is clamped to 1)",
    )
    parser.add_argument(
        rate_flag,
        dest="clip_rate",
        type=number_in(RATE_MIN, RATE_MAX),
        default=1.0,
        metavar="R",
        help=f"playback rate {RATE_MIN:g}..{RATE_MAX:g} (2 = twice as fast; default 1)",
    )
    parser.add_argument(
        "--loops",
        type=integer_in(0, LOOPS_MAX, what="--loops"),
        default=1,
        metavar="N",
        help=f"passes of the clip's loop region, 1..{LOOPS_MAX}; 0 = until stopped (default 1)",
    )


def _add_channel(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--channel",
        type=integer_in(1, MAX_CHANNELS, what="--channel"),
        default=None,
        metavar="N",
        help="1-based; default every channel",
    )


def add_clip_play_parsers(sub: Any) -> None:
    """Add ``play`` and ``stop`` to the ``vibsynth clip`` sub-parsers."""
    p = sub.add_parser(
        "play",
        help="play a clip on a running server (vibsynth serve)",
        description=PLAY_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", metavar="NAME", help="clip name (vibsynth clip list)")
    _add_channel(p)
    add_clip_play_arguments(p, rate_flag="--rate")
    p.add_argument(
        "--at",
        type=number_in(0.0, MAX_AT_S),
        default=None,
        metavar="S",
        help=f"start S seconds from now, at that exact sample (a timetagged bundle; at most {MAX_AT_S:g})",
    )
    add_server_arguments(p)
    p.set_defaults(func=run_play)
    p = sub.add_parser("stop", help="stop the clip playing on a running server; the channel glides back")
    _add_channel(p)
    p.add_argument(
        "--release",
        type=number_in(0.0, 10000.0),
        default=None,
        metavar="MS",
        help="glide back over MS (default: the channel's glide)",
    )
    add_server_arguments(p)
    p.set_defaults(func=run_stop)


def _prefix() -> str:
    """The server's OSC prefix from the user's config (``/vibsynth`` when it cannot be read)."""
    try:
        from vibsynth.settings.config import load_config

        prefix = load_config().settings.osc.prefix
    except Exception:  # noqa: BLE001 - a broken config must not stop a client from reaching the server
        prefix = "/vibsynth"
    return prefix.rstrip("/")


def _send(args: argparse.Namespace, method: str, values: tuple[object, ...], types: str, at: float | None) -> int:
    from vibsynth.cli.send import _is_error, exchange

    prefix = _prefix()
    address = f"{prefix}/{method}" if args.channel is None else f"{prefix}/ch/{args.channel}/{method}"
    data = encode_message(address, values, types)
    if at is not None:
        data = encode_bundle(time.time() + at, [data])
    host, port = server_address(args)
    with Client(host, port, prefix=prefix) as client:
        try:
            replies, answered = exchange(client, data, 0.0, confirm_s=args.timeout)
        except OSError as exc:
            raise ParameterError(f"cannot send to {host}:{port}: {exc.strerror or exc}") from None
    if not answered:
        print(f"vibsynth: error: {NoReplyError(host, port, args.timeout, address)}", file=sys.stderr)
        return 1
    errors = [r for r in replies if _is_error(r)]
    for error in errors:
        print(f"vibsynth: error: {error.args[0]}: {error.args[1]}", file=sys.stderr)
    return 1 if errors else 0


def run_play(args: argparse.Namespace) -> int:
    """Exit 0 once the server handled the play; 1 with its error line, or when no server answers."""
    return _send(args, "play", (args.name, args.gain, args.clip_rate, args.loops), "sffi", args.at)


def run_stop(args: argparse.Namespace) -> int:
    """Exit 0 once the server handled the stop; 1 with its error line, or when no server answers."""
    values: tuple[object, ...] = () if args.release is None else (args.release,)
    return _send(args, "stop", values, "f" * len(values), None)
