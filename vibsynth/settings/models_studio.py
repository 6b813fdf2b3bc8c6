"""The ``studio:`` config section: the browser workspace ``vibsynth serve`` serves (docs/studio.md)."""

from __future__ import annotations

from vibsynth.settings.fields import Section, setting

__all__ = ["STUDIO_PORT", "Studio"]

#: Default TCP port of the studio: next to OSC's 9570.
STUDIO_PORT = 9571


class Studio(Section):
    """``studio:``: the studio's HTTP + WebSocket server."""

    enabled: bool = setting(True, "serve the studio (a browser workspace) with serve")
    host: str = setting(
        "127.0.0.1",
        "other interfaces only by explicit choice (anyone who can reach it and has the token drives the actuator)",
        allowed="a host name or IP address",
        pattern=r"^\S+$",
    )
    port: int = setting(STUDIO_PORT, "TCP port of the studio; 0 = any free port", ge=0, le=65535)
