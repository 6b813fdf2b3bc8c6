"""A haptic design as the other tools describe it: intensity and sharpness (0..1) over time, plus taps.

The common ground of Apple Core Haptics (AHAP: intensity and sharpness) and Meta Haptics Studio
(``.haptic``: amplitude and frequency, both 0..1): :mod:`vibsynth.formats.ahap` and
:mod:`vibsynth.formats.meta_haptic` read their files into a :class:`HapticDesign` (with every
parameter curve and envelope already applied), and AHAP is written from one. Turning a design into
a vibsynth clip (the knob mapping) is :mod:`vibsynth.settings.clip_convert`'s job.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

__all__ = ["Segment", "Tap", "HapticDesign"]


@dataclass(frozen=True)
class Segment:
    """A piece of the continuous signal: linear from its start values to its end values.

    Attributes
    ----------
    t0, t1 : float
        Start and end in seconds, ``t0 < t1``.
    i0, i1 : float
        Intensity (AHAP HapticIntensity, Meta amplitude) 0..1 at ``t0`` and just before ``t1``.
    s0, s1 : float
        Sharpness (AHAP HapticSharpness, Meta frequency) 0..1 at ``t0`` and just before ``t1``.
    """

    t0: float
    t1: float
    i0: float
    i1: float
    s0: float
    s1: float

    @property
    def constant(self) -> bool:
        return self.i0 == self.i1 and self.s0 == self.s1

    def at(self, t: float) -> tuple[float, float]:
        """(intensity, sharpness) at a time within the segment."""
        u = (t - self.t0) / (self.t1 - self.t0)
        return self.i0 + u * (self.i1 - self.i0), self.s0 + u * (self.s1 - self.s0)


@dataclass(frozen=True)
class Tap:
    """A transient: AHAP HapticTransient, Meta emphasis. Times in seconds, values 0..1."""

    t: float
    intensity: float
    sharpness: float


@dataclass(frozen=True)
class HapticDesign:
    """Intensity and sharpness over time (piecewise linear, steps allowed) plus taps.

    Attributes
    ----------
    segments : tuple of Segment
        Consecutive (each starts where the previous ends), from 0 to ``duration_s``.
    taps : tuple of Tap
        Sorted by time.
    duration_s : float
    description : str
    tags : tuple of str
    ignored : tuple of str
        What the file held that the design does not carry (unknown fields, audio events,
        unsupported parameters, clamped values), one short phrase each, for one warning.
    """

    segments: tuple[Segment, ...]
    taps: tuple[Tap, ...]
    duration_s: float
    description: str = ""
    tags: tuple[str, ...] = ()
    ignored: tuple[str, ...] = ()

    def value_at(self, t: float) -> tuple[float, float]:
        """(intensity, sharpness) at a time (right-continuous at steps; held outside the segments)."""
        if not self.segments:
            return 0.0, 0.5
        starts = [s.t0 for s in self.segments]
        k = max(0, bisect_right(starts, t) - 1)
        seg = self.segments[k]
        if t >= seg.t1:
            return seg.i1, seg.s1
        if t <= seg.t0:
            return seg.i0, seg.s0
        return seg.at(t)
