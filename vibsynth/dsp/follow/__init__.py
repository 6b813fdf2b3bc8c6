"""Follow: the one tracker that turns a sound or vibration into knob trajectories.

* :class:`Tracker` (block by block, causal, bounded memory; live and offline),
  :class:`TrackerParams`, :class:`TrackFrames`;
* :func:`follow` / :func:`follow_channels` (a whole signal, latency compensated) and :func:`window_analysis` (the
  codec's windows, the same analysis).

Modes, focus and the mapping's reasons: docs/follow.md.
"""

from __future__ import annotations

from vibsynth.dsp.follow.frames import TrackFrames
from vibsynth.dsp.follow.offline import FollowResult, follow, follow_channels, window_analysis
from vibsynth.dsp.follow.params import FOCUSES, MODES, Focus, Mode, TrackerParams, default_params
from vibsynth.dsp.follow.tracker import Tracker

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
