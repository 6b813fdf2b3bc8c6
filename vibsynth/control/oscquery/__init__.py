"""OSCQuery and mDNS discovery: the OSC address space as a JSON tree, found by tools on the network.

* :mod:`~vibsynth.control.oscquery.tree` - nodes and the proposal's attribute rules;
* :mod:`~vibsynth.control.oscquery.methods` - the OSC methods as nodes (ranges from the settings);
* :mod:`~vibsynth.control.oscquery.server` - HTTP + WebSocket (LISTEN, value pushes, structure changes);
* :mod:`~vibsynth.control.oscquery.discovery` - zeroconf advertising and browsing;
* :mod:`~vibsynth.control.oscquery.adapter` - ``serve`` flags and construction from ``discovery:``.

:func:`oscquery_of` finds the running service of a controller, where another adapter (the VRChat
bridge) registers its nodes (``service.tree.register(table)``, ``service.server.structure_changed()``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from vibsynth.control.registry import Registry

if TYPE_CHECKING:
    from vibsynth.control.oscquery.adapter import OscQueryService

__all__ = ["attach", "detach", "oscquery_of"]

_services: Registry[OscQueryService] = Registry()


def attach(controller: Any, service: OscQueryService) -> None:
    """Make ``service`` the running OSCQuery service of ``controller`` (what :func:`oscquery_of` returns)."""
    _services.attach(controller, service)


def detach(controller: Any, service: OscQueryService) -> None:
    """Forget ``service`` (if it is still the controller's)."""
    _services.detach(controller, service)


def oscquery_of(controller: Any) -> OscQueryService | None:
    """The running OSCQuery service of ``controller`` (an adapter registers its nodes there), or None."""
    return _services.of(controller)
