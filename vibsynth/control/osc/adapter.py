"""The OSC adapter for ``vibsynth serve`` (contract of :mod:`vibsynth.control`): flags and construction."""

from __future__ import annotations

import argparse
import logging
import math
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.osc.transport import (
    TCP_IDLE_TIMEOUT_S,
    TCP_MAX_CONNECTIONS,
    TCP_MAX_PER_PEER,
)
from vibsynth.errors import ConfigError

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--osc-port``, ``--osc-host`` and ``--no-osc`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("OSC")
    group.add_argument(
        "--osc-port",
        type=int,
        default=None,
        metavar="PORT",
        help="UDP port of the OSC server (default: osc.port, 9570)",
    )
    group.add_argument(
        "--osc-host",
        default=None,
        metavar="HOST",
        help="address to listen on (default: osc.host, 127.0.0.1; 0.0.0.0 = every interface)",
    )
    group.add_argument("--no-osc", action="store_true", default=False, help="do not start the OSC server")


def _port(value: Any, key: str) -> int:
    try:
        port = int(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{key} must be a port number, got {value!r}") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"{key} {port} is outside [0, 65535]")
    return port


def create(
    config: Any, args: argparse.Namespace | None, controller: Controller, presets: Any = None
) -> OscServer | None:
    """Build (not start) the OSC server from the config and flags; None when disabled.

    Parameters
    ----------
    config : Config
        Effective configuration (``osc``, ``speed`` and ``audio`` sections are read).
    args : argparse.Namespace or None
        Parsed ``vibsynth serve`` flags (``--osc-port``, ``--osc-host``, ``--no-osc``).
    controller : Controller
    presets : object, optional
        The preset library (unused: presets are resolved by the controller).

    Raises
    ------
    ConfigError
        For invalid ``osc``/``speed`` settings.
    """
    data = getattr(config, "data", config) or {}
    osc = dict(data.get("osc") or {})
    if getattr(args, "no_osc", False) or not osc.get("enabled", True):
        log.info("OSC server disabled (%s)", "--no-osc" if getattr(args, "no_osc", False) else "osc.enabled: false")
        return None
    host = getattr(args, "osc_host", None) or osc.get("host") or "127.0.0.1"
    port_flag = getattr(args, "osc_port", None)
    port = _port(port_flag if port_flag is not None else osc.get("port", 9570), "osc.port")
    reply_port = osc.get("reply_port")
    reply_port = None if reply_port in (None, "", 0) else _port(reply_port, "osc.reply_port")
    speed = dict(data.get("speed") or {})
    curve = SpeedCurve(
        speed.get("curve", [[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]]),
        speed.get("balance_per_decade", 0.0) or 0.0,
    )
    try:
        horizon = float(osc.get("schedule_horizon_s", 10.0))
        rate = float(osc.get("notify_rate_hz", 30.0))
    except (TypeError, ValueError):
        raise ConfigError("osc.schedule_horizon_s and osc.notify_rate_hz must be numbers") from None
    if not (math.isfinite(horizon) and 0.0 <= horizon <= 3600.0):
        raise ConfigError(f"osc.schedule_horizon_s {horizon:g} is outside [0, 3600]")
    if not (math.isfinite(rate) and 0.0 < rate <= 1000.0):
        raise ConfigError(f"osc.notify_rate_hz {rate:g} is outside (0, 1000]")
    allow = osc.get("allow") or []
    if isinstance(allow, str):
        allow = [allow]
    tcp_limits = _tcp_limits(osc)
    block = (data.get("audio") or {}).get("block_size")
    return OscServer(
        controller,
        host=str(host),
        port=port,
        prefix=osc.get("prefix", "/vibsynth"),
        allow=allow,
        reply_port=reply_port,
        schedule_horizon_s=horizon,
        notify_rate_hz=rate,
        tcp=bool(osc.get("tcp", False)),
        speed_curve=curve,
        block_size=int(block) if isinstance(block, int) else None,
        **tcp_limits,
    )


def _tcp_limits(osc: dict) -> dict[str, Any]:
    """``tcp_max_connections``, ``tcp_max_per_peer``, ``tcp_idle_timeout_s`` from the ``osc`` section.

    Raises
    ------
    ConfigError
        For a value outside its range.
    """
    out: dict[str, Any] = {}
    for key, default, low, high in (
        ("tcp_max_connections", TCP_MAX_CONNECTIONS, 1, 1024),
        ("tcp_max_per_peer", TCP_MAX_PER_PEER, 1, 1024),
    ):
        value = osc.get(key, default)
        if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
            raise ConfigError(f"osc.{key} {value!r} is not an integer in [{low}, {high}]")
        out[key] = value
    idle = osc.get("tcp_idle_timeout_s", TCP_IDLE_TIMEOUT_S)
    if not isinstance(idle, (int, float)) or isinstance(idle, bool) or not (math.isfinite(idle) and 0 < idle <= 86400):
        raise ConfigError(f"osc.tcp_idle_timeout_s {idle!r} is not a number in (0, 86400] s")
    out["tcp_idle_timeout_s"] = float(idle)
    return out
