"""Follow: the one tracker that turns a sound or vibration into knob trajectories.

* :class:`Tracker` (block by block, causal, bounded memory; live and offline),
  :class:`TrackerParams`, :class:`TrackFrames`;
* :func:`follow` / :func:`follow_channels` (a whole signal, latency compensated) and :func:`window_analysis` (the
  codec's windows, the same analysis).

Modes, focus and the mapping's reasons: docs/follow.md.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from vibsynth.dsp.follow.params import FOCUSES, MODES, Focus, Mode, TrackerParams, default_params

if TYPE_CHECKING:
    from vibsynth.dsp.follow.frames import TrackFrames
    from vibsynth.dsp.follow.offline import FollowResult, follow, follow_channels, window_analysis
    from vibsynth.dsp.follow.tracker import Tracker

# The rest is imported on first use: the settings (so every command, at its start) need only the
# parameters, and the tracker's modules bring in scipy.signal (about a second of CPU).
_LAZY = {
    "TrackFrames": "frames",
    "FollowResult": "offline",
    "follow": "offline",
    "follow_channels": "offline",
    "window_analysis": "offline",
    "Tracker": "tracker",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
        globals()[name] = value  # once: later look-ups find it here
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "FOCUSES",
    "MODES",
    "Focus",
    "Mode",
    "FollowResult",
    "TrackFrames",
    "Tracker",
    "TrackerParams",
    "default_params",
    "follow",
    "follow_channels",
    "window_analysis",
]
