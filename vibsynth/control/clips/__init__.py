"""Haptic clips, played live: the timeline compiler, the player and its status (issue 16; docs/clips.md).

* :mod:`~vibsynth.control.clips.timeline` - clip + gain + rate + loops -> engine knob moves (pure);
* :mod:`~vibsynth.control.clips.player` - the control thread that keeps the playing clips'
  moves submitted ahead through the controller's ``clip`` layer;
* :mod:`~vibsynth.control.clips.status` - what plays, for ``/status``, ``get clip`` and the studio;
* :mod:`~vibsynth.control.clips.adapter` - ``vibsynth serve``'s wiring (a control adapter:
  the clip library, its hot reload and the player).

The OSC methods (``play``, ``stop``) are in :mod:`vibsynth.control.osc.clips`, the MIDI note
map in :mod:`vibsynth.control.midi.clipnotes`. They find the running player of a controller
with :func:`player_of`.
"""

from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from vibsynth.control.clips.player import ClipPlayer

__all__ = ["attach", "detach", "player_of"]

_lock = threading.Lock()
_players: weakref.WeakKeyDictionary[Any, ClipPlayer] = weakref.WeakKeyDictionary()


def attach(controller: Any, player: ClipPlayer) -> None:
    """Make ``player`` the clip player of ``controller`` (what :func:`player_of` returns)."""
    with _lock:
        _players[controller] = player


def detach(controller: Any, player: ClipPlayer) -> None:
    """Forget ``player`` (if it is still the controller's)."""
    with _lock:
        if _players.get(controller) is player:
            del _players[controller]


def player_of(controller: Any) -> ClipPlayer | None:
    """The running clip player of ``controller``, or None (not started)."""
    with _lock:
        return _players.get(controller)
