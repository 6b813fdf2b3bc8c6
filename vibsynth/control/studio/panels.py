"""The studio's panels with routes or threads of their own, installed on a server."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vibsynth.control.studio.status import StatusPanel

__all__ = ["install_panels"]


def install_panels(server: Any, config: Any = None, servers: Sequence[Any] = ()) -> None:
    """Add the status panel to ``server`` (a :class:`~vibsynth.control.studio.server.StudioServer`, not started)."""
    server.plugins.append(StatusPanel(server, servers))
