"""The studio's extension hook: another part of vibsynth adds a tab (an ES module) and HTTP routes.

The lab (``vibsynth/app/lab``) and the clip lane (``vibsynth/app/clips``) need the control
layer and the research layer at once, so they live in ``vibsynth/app`` and hand their tabs to
the studio server when ``vibsynth serve`` starts it (``vibsynth/app/studio_tabs.py`` lists
the modules; docs/studio.md, "Extensions", shows a whole example)::

    StudioExtension(
        name="lab",                          # URL prefix /ext/lab/, tab id
        title="Lab",                         # text of the tab
        script=Path(__file__).with_name("lab_tab.js"),   # served at /ext/lab/tab.js
        add_routes=add_lab_routes,           # add_lab_routes(app, host): routes under /ext/lab/
    )

Every route an extension adds is behind the studio's token check, origin check and body
size cap (they are the application's middlewares); the server refuses an extension whose
routes leave its ``/ext/<name>/`` prefix.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from vibsynth.errors import ConfigError

__all__ = ["EXTENSION_NAME", "StudioExtension", "StudioHost"]

#: An extension's name: its tab id and URL prefix ``/ext/<name>/``.
EXTENSION_NAME = r"^[a-z][a-z0-9-]{0,31}$"
#: Largest tab script served (an ES module written by hand, not a bundle).
MAX_SCRIPT_BYTES = 1 << 20


class StudioHost(Protocol):
    """What the studio server offers an extension's routes (the StudioServer itself)."""

    controller: Any

    def publish(self, extension: str, key: str, data: Any) -> None:
        """Push ``{"type": "ext", "extension", "key", "data"}`` to every open page (any thread; coalesced per key)."""
        ...


@dataclass(frozen=True)
class StudioExtension:
    """A tab of the studio page, with its routes.

    Attributes
    ----------
    name : str
        Matches :data:`EXTENSION_NAME`; the tab's id and the URL prefix ``/ext/<name>/``.
    title : str
        Text of the tab (1-40 characters).
    script : pathlib.Path
        An ES module served at ``/ext/<name>/tab.js``; the page imports it when the tab is
        first opened and calls its ``mount(panel, studio)`` export (docs/studio.md).
    add_routes : callable, optional
        ``add_routes(app, host)``: add aiohttp routes to ``app`` (an ``aiohttp.web.Application``),
        all under ``/ext/<name>/``; ``host`` is a :class:`StudioHost`. Handlers run on the
        studio's event loop: blocking work goes to ``loop.run_in_executor``.
    """

    name: str
    title: str
    script: Path
    add_routes: Callable[[Any, StudioHost], None] | None = None

    @property
    def prefix(self) -> str:
        """URL prefix of the extension's routes."""
        return f"/ext/{self.name}/"

    def check(self) -> None:
        """Refuse a malformed extension (a bug in the code that made it) with one line.

        Raises
        ------
        ConfigError
            Bad name or title, or a script that is not a readable file.
        """
        if not isinstance(self.name, str) or not re.fullmatch(EXTENSION_NAME, self.name):
            raise ConfigError(f"studio extension name {self.name!r}: must match {EXTENSION_NAME}")
        if not isinstance(self.title, str) or not 1 <= len(self.title.strip()) <= 40:
            raise ConfigError(f"studio extension {self.name!r}: title must be 1-40 characters, got {self.title!r}")
        script = Path(self.script)
        if not script.is_file() or script.suffix != ".js":
            raise ConfigError(f"studio extension {self.name!r}: script {script} is not a .js file")
        if script.stat().st_size > MAX_SCRIPT_BYTES:
            raise ConfigError(f"studio extension {self.name!r}: script {script} is over {MAX_SCRIPT_BYTES} bytes")
