"""OSCQuery and mDNS for ``vibsynth serve``: flags and construction from the ``discovery:`` section.

Not in :data:`vibsynth.control.ADAPTER_MODULES`: it describes the OSC server, so the service
builds it after the OSC adapter (:func:`create` gets the running OSC server).
"""

from __future__ import annotations

import argparse
import ipaddress
import logging
from collections.abc import Callable
from typing import Any

from vibsynth.control import oscquery
from vibsynth.control.controller import Controller
from vibsynth.control.oscquery.discovery import Advertiser, default_name
from vibsynth.control.oscquery.library import LibraryNodes
from vibsynth.control.oscquery.methods import knob_ranges, method_nodes, reads
from vibsynth.control.oscquery.server import OscQueryServer
from vibsynth.control.oscquery.tree import Tree
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["add_arguments", "create", "OscQueryService"]

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--oscquery-port`` and ``--no-discovery`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("discovery (OSCQuery, mDNS)")
    group.add_argument(
        "--oscquery-port",
        type=flag_type("discovery.oscquery_port"),
        default=None,
        metavar="PORT",
        help="TCP port of the OSCQuery server, HTTP + WebSocket (default: discovery.oscquery_port, 9572, or a free "
        "port when that one is taken; with this flag a taken port is an error; 0 = any free port)",
    )
    group.add_argument(
        "--no-discovery", action="store_true", default=False, help="no OSCQuery server and no mDNS advertising"
    )


class OscQueryService:
    """The OSCQuery server and its mDNS advertisement, started and stopped together (a ControlServer)."""

    name = "oscquery"

    def __init__(self, server: OscQueryServer, advertiser: Advertiser | None) -> None:
        self.server = server
        self.advertiser = advertiser
        self._previous_status: Callable[[], list[tuple[str, object]]] | None = None

    @property
    def tree(self) -> Tree:
        return self.server.tree

    def start(self) -> None:
        self.server.start()
        handler = self.server.handler
        previous = handler.extra_status
        self._previous_status = previous
        # the OSC server's /status (and so the studio's status panel, vibsynth status) shows these too
        handler.extra_status = lambda: [*(previous() if previous is not None else []), *self.status_pairs()]
        if self.advertiser is not None:
            self.advertiser.oscquery_port = self.server.port
            self.advertiser.start()
        oscquery.attach(self.server.controller, self)

    def stop(self) -> None:
        oscquery.detach(self.server.controller, self)
        if self.advertiser is not None:
            self.advertiser.stop()
        self.server.handler.extra_status = self._previous_status
        self.server.stop()

    def describe(self) -> str:
        text = self.server.describe()
        if self.advertiser is not None:
            text += f"; {self.advertiser.describe()}"
        return text

    def status_pairs(self) -> list[tuple[str, object]]:
        pairs = self.server.status_pairs()
        if self.advertiser is not None:
            pairs.append(("mdns_conflicts", self.advertiser.conflicts))
        return pairs


def _loopback(host: str) -> bool:
    try:
        return host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _names(library: Any) -> Callable[[], list[str]]:
    return (lambda: list(library.names())) if library is not None else (lambda: [])


def create(
    settings: VibsynthConfig,
    args: argparse.Namespace | None,
    controller: Controller,
    osc_server: Any,
    *,
    presets: Any = None,
    clips: Any = None,
) -> OscQueryService | None:
    """Build (not start) the OSCQuery server (and the advertiser) for a running OSC server; None when off.

    Parameters
    ----------
    settings : VibsynthConfig
        Its ``discovery`` and ``osc`` sections are read.
    args : argparse.Namespace or None
        ``oscquery_port``, ``no_discovery``, ``osc_host``.
    controller : Controller
    osc_server : OscServer or None
        The OSC server described (None: no OSC server, nothing to describe).
    presets, clips : library, optional
        Their names are the preset and clip nodes' RANGE VALS, and each entry is a node of its own
        (``/vibsynth/presets/NAME``, ``/vibsynth/clips/NAME``: :mod:`~vibsynth.control.oscquery.library`).
    """
    discovery = settings.discovery
    if osc_server is None or getattr(args, "no_discovery", False) or not discovery.enabled:
        log.info("OSCQuery and mDNS off")
        return None
    handler = osc_server.handler
    name = discovery.name or default_name()
    tree = Tree(
        method_nodes(handler, _names(presets), _names(clips)),
        reads(controller),
        root_description=f"{name}: haptic textures (docs/osc.md)",
    )
    intensity_range, balance_range = knob_ranges(controller)
    tree.register(
        LibraryNodes(handler.prefix, presets, clips, intensity_range=intensity_range, balance_range=balance_range)
    )
    tree.refresh()  # the library's nodes are in the tree from the first request
    port_flag = getattr(args, "oscquery_port", None)
    osc_host = str(getattr(args, "osc_host", None) or settings.osc.host)
    host_label = "".join(c if c.isalnum() else "-" for c in name).strip("-")[:50]
    server = OscQueryServer(
        tree,
        handler,
        controller,
        host=osc_host,
        port=port_flag if port_flag is not None else discovery.oscquery_port,
        osc_host=osc_host,
        osc_port=osc_server.port,
        allow=osc_server.udp.allow,
        name=name,
        local_names=(f"{host_label}.local",),
        port_fallback=port_flag is None,
    )
    advertiser = None
    addresses = list(discovery.interfaces) if discovery.interfaces else [osc_host]
    if discovery.advertise and not discovery.interfaces and _loopback(osc_host):
        # mDNS responders (Avahi, Bonjour) do not listen on loopback: tools find a local server
        # through a real interface, and a loopback-only server is reachable from this machine only
        log.info(
            "mDNS: not advertised: the OSC server listens on %s only (set osc.host or discovery.interfaces)", osc_host
        )
    elif discovery.advertise:
        advertiser = Advertiser(name, osc_server.port, server.port, addresses, count=controller.count_error)
    return OscQueryService(server, advertiser)
