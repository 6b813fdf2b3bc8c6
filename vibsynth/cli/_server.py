"""Reaching a running ``vibsynth serve``: ``--host``, ``--port`` and ``--timeout`` for client commands."""

from __future__ import annotations

import argparse

from vibsynth.cli._numbers import integer_in, positive_seconds
from vibsynth.errors import ParameterError

__all__ = ["add_server_arguments", "server_address"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 9570


def add_server_arguments(parser: argparse.ArgumentParser, *, timeout: float = 1.0) -> None:
    """Add ``--host``, ``--port`` (defaults: the config's ``osc.host``/``osc.port``) and ``--timeout``."""
    parser.add_argument("--host", default=None, help=f"server host (default: osc.host from the config, {DEFAULT_HOST})")
    parser.add_argument(
        "--port",
        type=integer_in(1, 65535, what="port"),
        default=None,
        help=f"server UDP port (default: osc.port from the config, {DEFAULT_PORT})",
    )
    parser.add_argument(
        "--timeout",
        type=positive_seconds,
        default=timeout,
        metavar="SECONDS",
        help=f"how long to wait for the server (default {timeout:g})",
    )


def server_address(args: argparse.Namespace) -> tuple[str, int]:
    """The server's host and port: the flags, else the user's config, else the defaults.

    A config that cannot be read does not stop a client: it falls back to the defaults.
    """
    host, port = args.host, args.port
    if host is None or port is None:
        try:
            from vibsynth.settings.config import load_config

            osc = load_config().settings.osc
            configured: tuple[str, int] = (osc.host, osc.port)
        except Exception:  # noqa: BLE001 - a broken config must not stop a client from reaching the server
            configured = (DEFAULT_HOST, DEFAULT_PORT)
        host = host or configured[0] or DEFAULT_HOST
        port = port if port is not None else configured[1] or DEFAULT_PORT
    if host in ("0.0.0.0", "::"):
        host = DEFAULT_HOST  # a server listening everywhere is reached on this machine
    if not 1 <= port <= 65535:
        raise ParameterError(f"--port {port} is outside [1, 65535]")
    return host, port
