"""Spatial textures: touch sources mixed onto a layout of actuators (issue 15; docs/vr.md).

* :mod:`~vibsynth.control.spatial.sources` - the sources' state: validated setters, glides, speed;
* :mod:`~vibsynth.control.spatial.mixer` - the control thread that mixes the sources in the
  paper's perceptual model (:mod:`vibsynth.dsp.spatial`) and drives the channels through the
  controller's ``sources`` layer;
* :mod:`~vibsynth.control.spatial.midi` - MIDI controllers bound to source coordinates;
* :mod:`~vibsynth.control.spatial.adapter` - ``vibsynth serve``'s wiring (a control adapter).

The OSC methods (``/vibsynth/source/{k}/...``) are in :mod:`vibsynth.control.osc.sources`.
The adapters find the running mixer of a controller with :func:`mixer_of`.
"""

from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from vibsynth.control.spatial.mixer import SourceMixer

__all__ = ["attach", "detach", "mixer_of"]

_lock = threading.Lock()
_mixers: weakref.WeakKeyDictionary[Any, SourceMixer] = weakref.WeakKeyDictionary()


def attach(controller: Any, mixer: SourceMixer) -> None:
    """Make ``mixer`` the sources' mixer of ``controller`` (what :func:`mixer_of` returns)."""
    with _lock:
        _mixers[controller] = mixer


def detach(controller: Any, mixer: SourceMixer) -> None:
    """Forget ``mixer`` (if it is still the controller's)."""
    with _lock:
        if _mixers.get(controller) is mixer:
            del _mixers[controller]


def mixer_of(controller: Any) -> SourceMixer | None:
    """The running mixer of ``controller``, or None (no layout configured, or not started)."""
    with _lock:
        return _mixers.get(controller)
