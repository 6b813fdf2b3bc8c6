"""The OSC adapter for ``vibsynth serve`` (contract of :mod:`vibsynth.control`): flags and construction."""

from __future__ import annotations

import argparse
import logging
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.models_config import VibsynthConfig

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--osc-port``, ``--osc-host`` and ``--no-osc`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("OSC")
    group.add_argument(
        "--osc-port",
        type=flag_type("osc.port"),
        default=None,
        metavar="PORT",
        help="UDP port of the OSC server (default: osc.port, 9570; 0 = any free port)",
    )
    group.add_argument(
        "--osc-host",
        type=flag_type("osc.host"),
        default=None,
        metavar="HOST",
        help="address to listen on (default: osc.host, 127.0.0.1; 0.0.0.0 = every interface)",
    )
    group.add_argument("--no-osc", action="store_true", default=False, help="do not start the OSC server")


def create(
    settings: VibsynthConfig, args: argparse.Namespace | None, controller: Controller, presets: Any = None
) -> OscServer | None:
    """Build (not start) the OSC server from the typed settings and flags; None when disabled.

    Parameters
    ----------
    settings : VibsynthConfig
        The typed settings (its ``osc``, ``speed`` and ``audio.block_size`` are read).
    args : argparse.Namespace or None
        Parsed ``vibsynth serve`` flags (``--osc-port``, ``--osc-host``, ``--no-osc``).
    controller : Controller
    presets : object, optional
        The preset library (unused: presets are resolved by the controller).

    """
    osc, speed = settings.osc, settings.speed
    if getattr(args, "no_osc", False) or not osc.enabled:
        log.info("OSC server disabled (%s)", "--no-osc" if getattr(args, "no_osc", False) else "osc.enabled: false")
        return None
    host = getattr(args, "osc_host", None) or osc.host
    port_flag = getattr(args, "osc_port", None)
    return OscServer(
        controller,
        host=str(host),
        port=port_flag if port_flag is not None else osc.port,
        prefix=osc.prefix,
        allow=list(osc.allow or []),
        reply_port=osc.reply_port,
        schedule_horizon_s=osc.schedule_horizon_s,
        notify_rate_hz=osc.notify_rate_hz,
        tcp=osc.tcp,
        receive_priority=osc.receive_priority,
        speed_curve=SpeedCurve(speed.curve, speed.balance_per_decade),
        block_size=settings.audio.block_size,
        tcp_max_connections=osc.tcp_max_connections,
        tcp_max_per_peer=osc.tcp_max_per_peer,
        tcp_idle_timeout_s=osc.tcp_idle_timeout_s,
    )
