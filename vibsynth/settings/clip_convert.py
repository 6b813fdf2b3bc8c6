"""Clips to and from the other tools' designs (AHAP, Meta ``.haptic``): the knob mapping.

Both tools describe a haptic by an intensity (AHAP HapticIntensity, Meta amplitude) and a
spectral quality (AHAP HapticSharpness, Meta frequency), both 0..1. vibsynth's two knobs are the
perceptual attributes of the paper, so the mapping is direct (``clips:`` settings, docs/clips.md):

* intensity knob = intensity ** ``clips.intensity_exponent`` (1 by default: the same number);
* balance = linear in sharpness between ``sharpness_0_balance`` (default ``knobs.balance_min``),
  ``sharpness_half_balance`` (0: sharpness 0.5 is the mean spectrum) and ``sharpness_1_balance``
  (default ``knobs.balance_max``): sharper is brighter;
* taps (AHAP HapticTransient, Meta emphasis) become transients decaying over
  ``clips.transient_decay_ms``.

Export inverts the same mapping. Curves are piecewise linear in the design; where the mapping is
not linear (an exponent other than 1, the kink at sharpness 0.5) segments are cut finely enough
that the clip stays within 0.005 of the exact mapping.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

from vibsynth.errors import ClipError
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap
from vibsynth.settings.clips import Clip, Keyframe, Transient, clip_from_data
from vibsynth.settings.models_clip import MAX_KEYFRAMES, MAX_TRANSIENTS
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.models_preset import NAME_PATTERN
from vibsynth.settings.validation import FixedLocator

__all__ = ["ClipMapping", "clip_from_design", "design_from_clip", "clip_name"]

#: A step in the design becomes a keyframe this long before it (the clip's keyframe times strictly increase).
STEP_MS = 0.001
#: Pieces of a smooth keyframe segment exported to AHAP (Core Haptics interpolates linearly).
PIECES = 16
#: Largest deviation from the exact mapping allowed between cuts (knob or design units).
TOLERANCE = 0.002


@dataclass(frozen=True)
class ClipMapping:
    """How design values (0..1) map onto the knobs, and back.

    Attributes
    ----------
    intensity_exponent : float
    balance_points : (float, float, float)
        Balance at sharpness 0, 0.5 and 1 (increasing).
    transient_decay_ms : float
    """

    intensity_exponent: float = 1.0
    balance_points: tuple[float, float, float] = (-3.5, 0.0, 3.5)
    transient_decay_ms: float = 40.0

    @classmethod
    def from_settings(cls, settings: VibsynthConfig) -> ClipMapping:
        """The ``clips:`` settings; null balance ends are the live range ``knobs.balance_min/max``."""
        clips, knobs = settings.clips, settings.knobs
        low, high = clips.sharpness_0_balance, clips.sharpness_1_balance
        points = (
            float(knobs.balance_min if low is None else low),
            float(clips.sharpness_half_balance),
            float(knobs.balance_max if high is None else high),
        )
        if not points[0] < points[1] < points[2]:
            raise ClipError(
                f"clip mapping: balances {points[0]:g} < {points[1]:g} < {points[2]:g} at sharpness 0, 0.5, 1 "
                "must increase (clips.sharpness_*_balance, knobs.balance_min/max)"
            )
        return cls(float(clips.intensity_exponent), points, float(clips.transient_decay_ms))

    @property
    def linear(self) -> bool:
        return self.intensity_exponent == 1.0

    def intensity(self, x: float) -> float:
        """Knob intensity of a design intensity."""
        return math.pow(max(float(x), 0.0), self.intensity_exponent)

    def design_intensity(self, knob: float) -> float:
        """Design intensity of a knob intensity."""
        return math.pow(max(float(knob), 0.0), 1.0 / self.intensity_exponent)

    def balance(self, sharpness: float) -> float:
        """Balance of a sharpness (piecewise linear through the three points)."""
        b0, b1, b2 = self.balance_points
        s = min(max(float(sharpness), 0.0), 1.0)
        return b0 + 2 * s * (b1 - b0) if s <= 0.5 else b1 + (2 * s - 1) * (b2 - b1)

    def sharpness(self, balance: float) -> float:
        """Sharpness of a balance (clamped to 0..1 outside the mapped range)."""
        b0, b1, b2 = self.balance_points
        s = 0.5 * (balance - b0) / (b1 - b0) if balance <= b1 else 0.5 + 0.5 * (balance - b1) / (b2 - b1)
        return min(max(s, 0.0), 1.0)


# --------------------------------------------------------------------------- design -> clip
def clip_name(stem: str) -> str:
    """A valid clip name from a file stem (``Boing 2!`` -> ``Boing-2``)."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", stem).strip("-._")[:64] or "imported"
    return name if re.fullmatch(NAME_PATTERN, name) else "imported"


def _power_cuts(t0: float, t1: float, x0: float, x1: float, exponent: float, *, measured_before: bool) -> list[float]:
    """Times inside [t0, t1] where ``x ** exponent`` (x linear in t) is cut so that straight lines
    between the cuts stay within :data:`TOLERANCE` of it.

    The deviation is measured in design units (AHAP / Meta values): after mapping back with
    ``1 / exponent`` when ``measured_before`` (an import: x is the design value), as is otherwise
    (an export: the result is the design value).
    """
    if exponent == 1.0 or x0 == x1:
        return []
    back = 1.0 / exponent

    def deviation(xa: float, xb: float) -> float:
        xm = 0.5 * (xa + xb)
        chord = 0.5 * (math.pow(xa, exponent) + math.pow(xb, exponent))
        if measured_before:
            return abs(math.pow(chord, back) - xm)
        return abs(math.pow(xm, exponent) - chord)

    out: list[float] = []
    stack = [(t0, t1, x0, x1, 0)]
    while stack:
        a, b, xa, xb, depth = stack.pop()
        if depth >= 14 or deviation(xa, xb) <= TOLERANCE:
            continue
        m, xm = 0.5 * (a + b), 0.5 * (xa + xb)
        out.append(m)
        stack += [(a, m, xa, xm, depth + 1), (m, b, xm, xb, depth + 1)]
    return sorted(out)


def _cuts(seg: Segment, mapping: ClipMapping) -> list[float]:
    """Times inside a segment where the mapped curve needs a keyframe to stay linear enough."""
    cuts: list[float] = []
    if (seg.s0 - 0.5) * (seg.s1 - 0.5) < 0:  # the kink of the balance mapping
        cuts.append(seg.t0 + (0.5 - seg.s0) / (seg.s1 - seg.s0) * (seg.t1 - seg.t0))
    cuts += _power_cuts(seg.t0, seg.t1, seg.i0, seg.i1, mapping.intensity_exponent, measured_before=True)
    return sorted(cuts)


def _pieces(seg: Segment, mapping: ClipMapping) -> Iterable[Segment]:
    edges = [seg.t0, *_cuts(seg, mapping), seg.t1]
    for a, b in zip(edges, edges[1:]):
        ia, sa = seg.at(a) if a > seg.t0 else (seg.i0, seg.s0)
        ib, sb = seg.at(b) if b < seg.t1 else (seg.i1, seg.s1)
        yield Segment(a, b, ia, ib, sa, sb)


def clip_from_design(design: HapticDesign, name: str, mapping: ClipMapping, *, description: str | None = None) -> Clip:
    """A clip playing the design through the mapping (see the module notes).

    Raises
    ------
    ClipError
        The design needs more keyframes or transients than a clip holds.
    """
    keys: list[Keyframe] = []
    segments = [p for seg in design.segments for p in _pieces(seg, mapping)]
    for k, seg in enumerate(segments):
        t0, t1 = seg.t0 * 1000.0, seg.t1 * 1000.0
        start = Keyframe(t0, mapping.intensity(seg.i0), mapping.balance(seg.s0))
        if seg.constant:
            if (
                keys
                and keys[-1].interp == "hold"
                and (keys[-1].intensity, keys[-1].balance)
                == (
                    start.intensity,
                    start.balance,
                )
            ):
                continue  # the same value goes on
            keys.append(Keyframe(t0, start.intensity, start.balance, "hold"))
            continue
        keys.append(start)
        end = (mapping.intensity(seg.i1), mapping.balance(seg.s1))
        following = segments[k + 1] if k + 1 < len(segments) else None
        if following is None:
            keys.append(Keyframe(t1, *end, "hold"))
        elif (following.i0, following.s0) != (seg.i1, seg.s1):  # a step at t1: reach the end value first
            keys.append(Keyframe(max(t1 - STEP_MS, (t0 + t1) / 2), *end, "hold"))
    keys = _increasing(keys)
    if not keys:  # taps only
        keys.append(Keyframe(0.0, 0.0, mapping.balance(0.5), "hold"))
    transients = [
        Transient(
            tap.t * 1000.0, mapping.intensity(tap.intensity), mapping.balance(tap.sharpness), mapping.transient_decay_ms
        )
        for tap in design.taps
    ]
    if len(keys) > MAX_KEYFRAMES or len(transients) > MAX_TRANSIENTS:
        raise ClipError(
            f"the design needs {len(keys):,} keyframes and {len(transients):,} transients; a clip holds at most "
            f"{MAX_KEYFRAMES:,} and {MAX_TRANSIENTS:,} (shorten or simplify it)"
        )
    last_ms = max([design.duration_s * 1000.0, keys[-1].t_ms] + [t.t_ms + t.decay_ms for t in transients])
    clip = Clip(
        name=name,
        duration_ms=last_ms if last_ms > 0 else 1.0,
        keyframes=tuple(keys),
        transients=tuple(transients),
        tags=tuple(design.tags),
        description=design.description if description is None else description,
    )
    # a last check by the schema (file order, ranges) so that an import never writes what cannot be read
    return clip_from_data(clip.to_dict(), FixedLocator(f"clip imported as {name!r}"), name)


def _increasing(keys: list[Keyframe]) -> list[Keyframe]:
    """Keyframes at strictly increasing times as a file writes them (6 decimals): of two closer
    than that, the later one stays."""
    out: list[Keyframe] = []
    for key in keys:
        while out and round(out[-1].t_ms, 6) >= round(key.t_ms, 6):
            out.pop()
        out.append(key)
    return out


# --------------------------------------------------------------------------- clip -> design
def _knob_pieces(clip: Clip) -> Iterable[tuple[float, float, float, float, float, float]]:
    """(t0, t1, intensity0, intensity1, balance0, balance1) pieces of the clip's curve, linear each, in ms."""
    keys = clip.keyframes
    if keys[0].t_ms > 0:
        k = keys[0]
        yield 0.0, k.t_ms, k.intensity, k.intensity, k.balance, k.balance
    for a, b in zip(keys, keys[1:]):
        if a.interp == "hold":
            yield a.t_ms, b.t_ms, a.intensity, a.intensity, a.balance, a.balance
        elif a.interp == "linear":
            yield a.t_ms, b.t_ms, a.intensity, b.intensity, a.balance, b.balance
        else:
            edges = [a.t_ms + j / PIECES * (b.t_ms - a.t_ms) for j in range(PIECES + 1)]
            values = [clip.value_at(t) for t in edges[:-1]] + [(b.intensity, b.balance)]
            for j in range(PIECES):
                yield edges[j], edges[j + 1], values[j][0], values[j + 1][0], values[j][1], values[j + 1][1]
    last = keys[-1]
    if clip.duration_ms > last.t_ms:
        yield last.t_ms, clip.duration_ms, last.intensity, last.intensity, last.balance, last.balance


def design_from_clip(clip: Clip, mapping: ClipMapping) -> HapticDesign:
    """The clip as a design (inverse mapping), for AHAP export.

    A transient's decay has no counterpart in AHAP (a HapticTransient has a fixed shape): it is
    dropped. A step (a short ``hold`` keyframe just before a jump, as :func:`clip_from_design`
    writes it) is folded back into the ramp before it.
    """
    b1 = mapping.balance_points[1]
    segments: list[Segment] = []
    for t0, t1, i0, i1, bal0, bal1 in _knob_pieces(clip):
        if t1 <= t0:
            continue
        edges = [t0, t1]
        if (bal0 - b1) * (bal1 - b1) < 0:
            edges.insert(1, t0 + (b1 - bal0) / (bal1 - bal0) * (t1 - t0))
        edges = sorted({*edges, *_power_cuts(t0, t1, i0, i1, 1.0 / mapping.intensity_exponent, measured_before=False)})
        for a, b in zip(edges, edges[1:]):
            ua, ub = (a - t0) / (t1 - t0), (b - t0) / (t1 - t0)
            ia, ib = i0 + ua * (i1 - i0), i0 + ub * (i1 - i0)
            ba, bb = bal0 + ua * (bal1 - bal0), bal0 + ub * (bal1 - bal0)
            seg = Segment(
                a / 1000.0,
                b / 1000.0,
                mapping.design_intensity(ia),
                mapping.design_intensity(ib),
                mapping.sharpness(ba),
                mapping.sharpness(bb),
            )
            last = segments[-1] if segments else None
            tiny = (b - a) <= 2 * STEP_MS
            if (
                last is not None
                and tiny
                and seg.constant
                and not last.constant
                and (last.i1, last.s1) == (seg.i0, seg.s0)
            ):
                segments[-1] = Segment(last.t0, seg.t1, last.i0, last.i1, last.s0, last.s1)
                continue
            segments.append(seg)
    taps = tuple(
        Tap(t.t_ms / 1000.0, mapping.design_intensity(t.intensity), mapping.sharpness(t.balance))
        for t in clip.transients
    )
    return HapticDesign(tuple(segments), taps, clip.duration_ms / 1000.0, clip.description, clip.tags)
