"""The method tables every OSC server registers into its handler: the touch sources, the clips, follow.

The handler knows only the registration contract (:mod:`~vibsynth.control.osc.methods`); the
tables know only the controller and the prefix. This module, above both, puts them together
(:class:`~vibsynth.control.osc.server.OscServer` calls it; so do tests of a bare handler).
"""

from __future__ import annotations

from vibsynth.control.osc.clips import ClipMethods
from vibsynth.control.osc.follow import FollowMethods
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.sources import SourceMethods

__all__ = ["register_tables"]


def register_tables(handler: OscHandler) -> OscHandler:
    """Register the sources' (``/vibsynth/source/{k}/...``), clips' and follow's methods into ``handler``."""
    handler.register(SourceMethods(handler.controller, handler.prefix))  # docs/vr.md
    handler.register(ClipMethods(handler.controller, handler.prefix))  # play, stop, get clip (docs/clips.md)
    handler.register(FollowMethods(handler.controller, handler.prefix))  # follow/..., ch/{n}/follow (docs/follow.md)
    return handler
