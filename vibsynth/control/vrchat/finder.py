"""VRChat found over mDNS: its ``_oscjson._tcp`` service (``VRChat-Client-XXXXXX``) and the OSC port in its HOST_INFO.

VRChat (since 2023.3.1) advertises ``VRChat-Client-`` followed by six hex digits as an
``_oscjson._tcp`` and an ``_osc._udp`` service; its OSCQuery ``HOST_INFO`` names its OSC input
(``OSC_IP``, ``OSC_PORT``, 9000 by default). VRChat also browses for OSCQuery services and sends
avatar parameters to those whose tree has ``/avatar``: once it is found, it reaches our OSC port
that way. When it is not found, ``vrchat.host``/``vrchat.send_port`` (9000) say where it listens
and it sends to its output port ``vrchat.listen_port`` (9001).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from vibsynth.control.oscquery.discovery import Found

__all__ = ["SERVICE_PREFIX", "VrchatAddress", "pick"]

#: The instance names VRChat advertises.
SERVICE_PREFIX = "VRChat-Client-"


@dataclass(frozen=True)
class VrchatAddress:
    """Where VRChat takes OSC (``host``, ``port``), whether mDNS said so (``found``), and its
    OSCQuery server (``oscquery_url``, "" when not found)."""

    host: str
    port: int
    found: bool
    oscquery_url: str = ""

    def describe(self) -> str:
        return f"udp://{self.host}:{self.port} ({'found over mDNS' if self.found else 'not found; vrchat.send_port'})"


def pick(services: Sequence[Found], host: str, port: int) -> VrchatAddress:
    """VRChat's OSC input among discovered services (the first ``VRChat-Client-*`` with a HOST_INFO),
    else the fallback ``host``:``port``."""
    for service in services:
        if service.name.startswith(SERVICE_PREFIX) and service.osc_host and service.osc_port:
            return VrchatAddress(service.osc_host, int(service.osc_port), True, service.oscquery_url)
    return VrchatAddress(host, int(port), False)
