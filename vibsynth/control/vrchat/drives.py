"""The two drives of an avatar parameter, as pure state (times passed in, no threads).

``level``: the value is the amount (a proximity 0..1 is the intensity); VRChat sends a parameter
only when it changes, so a resting touch holds its level.

``velocity``: the rate of change of the value is the amount, up to ``full`` units per second
(faster = brighter: the balance rises with it); after the last change the amount falls linearly
to 0 over ``fade_s``, as a still finger feels no texture. A first value has no rate (it starts
nothing); values closer together in time than :data:`MIN_DT_S` count as that far apart (VRChat
may deliver several frames' changes at once).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["MIN_DT_S", "Velocity", "level_amount", "crossed"]

#: Shortest time between two changes the rate is measured over (a 120 Hz frame).
MIN_DT_S = 1.0 / 120.0


def level_amount(value: float) -> float:
    """A level drive's amount: the value clipped to 0..1."""
    return min(max(value, 0.0), 1.0)


def crossed(previous: float, value: float, threshold: float) -> bool:
    """Did the value rise across ``threshold`` (``previous <= threshold < value``): a bool's rising edge."""
    return previous <= threshold < value


@dataclass
class Velocity:
    """The envelope of one ``velocity`` drive.

    Parameters
    ----------
    full : float
        Rate (value units per second) of the full amount.
    fade_s : float
        Fade to 0 after the last change.
    """

    full: float
    fade_s: float
    value: float | None = None
    time: float = -math.inf
    peak: float = 0.0  # the amount at the last change (0..1)

    def change(self, value: float, t: float) -> None:
        """A new value at time ``t`` (seconds); a repeated value is no change."""
        if self.value is not None and value == self.value:
            return
        if self.value is None:
            self.peak = 0.0
        else:
            rate = abs(value - self.value) / max(t - self.time, MIN_DT_S)
            self.peak = min(rate / self.full, 1.0)
        self.value, self.time = value, t

    def amount(self, t: float) -> float:
        """The amount at time ``t``: the last change's, faded linearly over ``fade_s`` since."""
        if self.peak <= 0.0:
            return 0.0
        return self.peak * max(0.0, 1.0 - (t - self.time) / self.fade_s)

    def active(self, t: float) -> bool:
        """Still sounding (or fading) at ``t``."""
        return self.peak > 0.0 and t - self.time < self.fade_s

    def reset(self) -> None:
        self.value, self.time, self.peak = None, -math.inf, 0.0
