"""The ``discovery:`` config section: OSCQuery (the address space as JSON) and mDNS advertising (docs/osc.md)."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from vibsynth.settings.fields import Section, setting

__all__ = ["OSCQUERY_PORT", "SERVICE_NAME", "Discovery"]

#: Default TCP port of the OSCQuery server (HTTP + WebSocket): next to the studio's 9571.
OSCQUERY_PORT = 9572
#: Service names (mDNS instance names): printable, no dots, at most 63 bytes (an mDNS label).
SERVICE_NAME = r"^[^.\x00-\x1f]{1,63}$"


class Discovery(Section):
    """``discovery:``: the OSCQuery server and the mDNS (zeroconf) advertisement of the OSC services."""

    enabled: bool = setting(True, "serve the OSCQuery tree and advertise _oscjson._tcp and _osc._udp over mDNS")
    advertise: bool = setting(True, "advertise over mDNS (false: OSCQuery only, found by its address)")
    name: str | None = setting(
        None,
        "the service name tools show; null = 'vibsynth on HOSTNAME'",
        allowed="up to 63 characters, no dots, or null",
        pattern=SERVICE_NAME,
    )
    interfaces: list[Annotated[str, Field(pattern=r"^\S+$")]] | None = setting(
        None,
        "IP addresses to advertise on; null = the OSC server's (osc.host; every interface for 0.0.0.0)",
        allowed="a list of IP addresses, or null",
    )
    oscquery_port: int = setting(
        OSCQUERY_PORT, "TCP port of the OSCQuery server (HTTP + WebSocket); 0 = any free port", ge=0, le=65535
    )
