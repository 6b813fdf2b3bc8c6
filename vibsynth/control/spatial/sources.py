"""The state of the touch sources: validated setters, position glides and speed, no threads.

A :class:`SourceTable` holds up to :data:`~vibsynth.settings.models_sources.MAX_SOURCES`
sources, numbered from 0 here (adapters translate from the 1-based addresses). Every setter
validates its value first and changes nothing when it is refused, like the controller's
knobs. Times are seconds of one monotonic clock, passed in, so the table is deterministic.

Motion: a new position glides from where the source is at that moment to the target over
``glide_s`` (linear in space); an off source jumps. Speed: the path a source's requested
positions describe over the last ``speed_window_s`` seconds, divided by the time since the
first of them (so it falls to 0 within one window when positions stop coming or stop
changing).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

from vibsynth.control.controller import KnobLimits, PresetLike, check_finite, check_range
from vibsynth.dsp.spatial import check_rolloff
from vibsynth.errors import ParameterError
from vibsynth.settings.models_sources import MAX_SOURCES, POSITION_LIMIT_M

__all__ = ["Position", "SourceDefaults", "Source", "SourceView", "SourceTable", "SETTING_NAMES"]

Position = tuple[float, float, float]

#: What ``get`` reports of a source (and the setter each answers in).
SETTING_NAMES = ("pos", "texture", "intensity", "balance", "preset", "radius", "rolloff", "on", "speed")

#: Positions kept per source for its speed (a flood of positions keeps only the newest).
_SPEED_SAMPLES = 64


@dataclass(frozen=True)
class SourceDefaults:
    """What a new source starts with, and the limits of its settings.

    Attributes
    ----------
    radius_m, rolloff, glide_s, speed, speed_window_s
        See the ``sources:`` config section.
    radius_max_m : float
        Largest radius a control may set.
    limits : KnobLimits
        The live balance range (as for channels).
    """

    radius_m: float = 0.05
    rolloff: str = "smooth"
    glide_s: float = 0.02
    speed: bool = False
    speed_window_s: float = 0.1
    radius_max_m: float = POSITION_LIMIT_M
    limits: KnobLimits = KnobLimits()


@dataclass
class Source:
    """One source (mutable; held by :class:`SourceTable` under its owner's lock)."""

    radius: float
    rolloff: str
    speed: bool
    on: bool = False
    intensity: float = 0.0
    balance: float = 0.0
    preset: str | None = None
    target: Position = (0.0, 0.0, 0.0)
    start: Position = (0.0, 0.0, 0.0)
    start_time: float = 0.0
    end_time: float = 0.0
    samples: deque[tuple[float, Position]] = field(default_factory=lambda: deque(maxlen=_SPEED_SAMPLES))

    def position_at(self, t: float) -> Position:
        """Where the source is at time ``t`` (on its glide to the target)."""
        if t >= self.end_time or self.end_time <= self.start_time:
            return self.target
        f = max(0.0, (t - self.start_time) / (self.end_time - self.start_time))
        s, e = self.start, self.target
        return (s[0] + f * (e[0] - s[0]), s[1] + f * (e[1] - s[1]), s[2] + f * (e[2] - s[2]))

    def speed_at(self, t: float, window_s: float) -> float:
        """Speed in mm/s at time ``t`` from the positions requested in the last ``window_s``."""
        recent = [(ts, p) for ts, p in self.samples if t - window_s <= ts <= t]
        if len(recent) < 2 or t <= recent[0][0]:
            return 0.0
        path = sum(math.dist(a[1], b[1]) for a, b in zip(recent, recent[1:]))
        return 1000.0 * path / (t - recent[0][0])


@dataclass(frozen=True)
class SourceView:
    """A snapshot of one source for the mixer and for queries.

    Attributes
    ----------
    index : int
        0-based.
    position : Position
        Where it is at the snapshot's time.
    target : Position
        Where it was last asked to go.
    moving : bool
        Still gliding, or its speed still changes.
    """

    index: int
    on: bool
    position: Position
    target: Position
    radius: float
    rolloff: str
    intensity: float
    balance: float
    preset: str | None
    speed: bool
    speed_mm_s: float
    moving: bool


class SourceTable:
    """Up to 16 sources with validated setters (not thread-safe: the owner locks).

    Parameters
    ----------
    defaults : SourceDefaults
    preset_resolver : callable, optional
        ``name -> PresetLike`` (raises :class:`~vibsynth.errors.PresetError` for unknown names).
    """

    def __init__(
        self, defaults: SourceDefaults = SourceDefaults(), *, preset_resolver: Callable[[str], PresetLike] | None = None
    ) -> None:
        self.defaults = defaults
        self.preset_resolver = preset_resolver
        self._sources = [self._new() for _ in range(MAX_SOURCES)]

    def _new(self) -> Source:
        d = self.defaults
        return Source(radius=d.radius_m, rolloff=d.rolloff, speed=d.speed)

    def __len__(self) -> int:
        return len(self._sources)

    def _get(self, index: int) -> Source:
        if not 0 <= index < len(self._sources):
            raise ParameterError(f"source {index + 1} does not exist (sources are 1..{len(self._sources)})")
        return self._sources[index]

    # ------------------------------------------------------------------ validation (no change)
    @staticmethod
    def check_position(values: tuple[float, ...]) -> Position:
        """A position from 2 or 3 coordinates (z = 0), each finite and within the limits."""
        if len(values) not in (2, 3):
            raise ParameterError(f"a position has 2 or 3 coordinates (x, y[, z]), got {len(values)}")
        coords = [check_range(f"{axis} (m)", v, -POSITION_LIMIT_M, POSITION_LIMIT_M) for axis, v in zip("xyz", values)]
        return (coords[0], coords[1], coords[2] if len(coords) == 3 else 0.0)

    def check_radius(self, value: float) -> float:
        radius = check_finite("radius (m)", value)
        high = self.defaults.radius_max_m
        if not 0.0 < radius <= high:
            raise ParameterError(f"radius (m) {radius:g} is outside the allowed range (0, {high:g}]")
        return radius

    @staticmethod
    def check_intensity(value: float) -> float:
        return check_range("intensity", value, 0.0, 1.0)

    def check_balance(self, value: float) -> float:
        limits = self.defaults.limits
        return check_range("balance", value, limits.balance_min, limits.balance_max)

    def resolve_preset(self, name: str) -> PresetLike:
        """The preset of that name, its balance within the live range (as channels play it)."""
        if self.preset_resolver is None:
            raise ParameterError("no preset library is loaded")
        return self.preset_resolver(name)

    # ------------------------------------------------------------------ setters
    def set_position(self, index: int, position: Position, now: float) -> None:
        """Glide to ``position`` from where the source is at ``now`` (an off source jumps)."""
        src = self._get(index)
        here = src.position_at(now)
        src.samples.append((now, position))
        glide = self.defaults.glide_s
        if not src.on or glide <= 0.0:
            src.start, src.target, src.start_time, src.end_time = position, position, now, now
        else:
            src.start, src.target, src.start_time, src.end_time = here, position, now, now + glide

    def set_axis(self, index: int, axis: int, value: float, now: float) -> None:
        """Move one coordinate (0 = x, 1 = y, 2 = z) of the target (MIDI controllers)."""
        target = list(self._get(index).target)
        target[axis] = value
        self.set_position(index, self.check_position(tuple(target)), now)

    def set_texture(self, index: int, intensity: float | None = None, balance: float | None = None) -> None:
        src = self._get(index)
        if intensity is not None:
            src.intensity = intensity
        if balance is not None:
            src.balance = balance
        src.preset = None

    def set_preset(self, index: int, preset: PresetLike) -> None:
        src = self._get(index)
        limits = self.defaults.limits
        src.intensity = float(preset.intensity)
        src.balance = min(max(float(preset.balance), limits.balance_min), limits.balance_max)
        src.preset = preset.name

    def set_radius(self, index: int, radius: float) -> None:
        self._get(index).radius = radius

    def set_rolloff(self, index: int, law: str) -> None:
        self._get(index).rolloff = check_rolloff(law)

    def set_on(self, index: int, on: bool, now: float) -> None:
        src = self._get(index)
        if on and not src.on:
            src.start, src.start_time, src.end_time = src.target, now, now  # it appears where it was sent
        src.on = on

    def set_speed(self, index: int, speed: bool) -> None:
        self._get(index).speed = speed

    def all_off(self) -> None:
        """Every source off (panic); positions and knobs are kept."""
        for src in self._sources:
            src.on = False

    # ------------------------------------------------------------------ snapshots
    def view(self, index: int, at: float, now: float | None = None) -> SourceView:
        """One source where it is at time ``at``, with its speed as measured at ``now`` (default ``at``)."""
        src = self._get(index)
        window = self.defaults.speed_window_s
        now = at if now is None else now
        speed = src.speed_at(now, window) if src.speed else 0.0
        speed_changing = src.speed and any(ts >= now - window for ts, _ in src.samples)
        return SourceView(
            index=index,
            on=src.on,
            position=src.position_at(at),
            target=src.target,
            radius=src.radius,
            rolloff=src.rolloff,
            intensity=src.intensity,
            balance=src.balance,
            preset=src.preset,
            speed=src.speed,
            speed_mm_s=speed,
            moving=src.on and (at < src.end_time or speed_changing),
        )

    def views(self, at: float, now: float | None = None) -> list[SourceView]:
        """Every source at time ``at`` (speeds measured at ``now``, default ``at``)."""
        return [self.view(i, at, now) for i in range(len(self._sources))]

    def copy_of(self, index: int) -> Source:
        """A copy of one source's state (tests)."""
        src = self._get(index)
        return replace(src, samples=deque(src.samples, maxlen=_SPEED_SAMPLES))
