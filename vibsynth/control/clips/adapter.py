"""The clips' adapter for ``vibsynth serve`` (contract of :mod:`vibsynth.control`): library, hot reload, player.

``create`` loads the clip library (shipped clips + ``clips.user_dir``) and builds the
:class:`~vibsynth.control.clips.player.ClipPlayer`; ``start`` attaches it to the controller
(the OSC and MIDI adapters find it with :func:`vibsynth.control.clips.player_of`), starts its
control thread and, with ``clips.watch``, the library's hot reload. A clip edited while
it plays keeps playing as it was; the next play uses the new version.
"""

from __future__ import annotations

import argparse
import logging
from typing import Any

from vibsynth.control import clips
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.controller import Controller
from vibsynth.settings.clips import ClipLibrary, ClipWatcher, load_clip_library
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["ClipService", "add_arguments", "create"]

log = logging.getLogger(__name__)


class ClipService:
    """The clip library (hot reloaded) and the player, started and stopped with the service.

    Parameters
    ----------
    controller : Controller
    library : ClipLibrary
    watch : bool
        Reload the library's folders while serving.
    prefix : str
        The OSC prefix, for the start-up line.
    """

    name = "clips"

    def __init__(
        self, controller: Controller, library: ClipLibrary, *, watch: bool = True, prefix: str = "/vibsynth"
    ) -> None:
        self.controller = controller
        self.prefix = prefix.rstrip("/")
        self.library = library
        self.player = ClipPlayer(controller, library.get)
        self.watcher = ClipWatcher(library, self._changed, interval_s=0.5) if watch else None

    def _changed(self, name: str) -> None:
        log.info("clip %r changed; its next play uses the new version", name)

    def start(self) -> None:
        clips.attach(self.controller, self.player)
        self.player.start()
        if self.watcher is not None:
            self.watcher.start()

    def stop(self) -> None:
        """Stop the hot reload, then the clips still playing (they glide back), then the player."""
        if self.watcher is not None:
            self.watcher.stop()
        self.player.close()
        clips.detach(self.controller, self.player)

    def describe(self) -> str:
        count = len(self.library.items())
        reload = ", hot reload" if self.watcher is not None else ""
        return f"clips: {count} in the library{reload} (play one with {self.prefix}/play NAME, or a MIDI note)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The clips add no ``vibsynth serve`` flags (the ``clips:`` and ``midi_clips:`` config sections say it all)."""


def create(
    settings: VibsynthConfig, args: argparse.Namespace | None, controller: Controller, presets: Any = None
) -> ClipService:
    """Build (not start) the clip library (``clips:``) and player (OSC prefix ``osc.prefix``)."""
    return ClipService(controller, load_clip_library(settings), watch=settings.clips.watch, prefix=settings.osc.prefix)
