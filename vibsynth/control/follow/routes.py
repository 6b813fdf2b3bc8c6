"""Which inputs drive which output channel or touch source, and with which tracker parameters.

The typed ``follow:`` section (:class:`~vibsynth.settings.models_follow.Follow`) names routes;
:func:`plan_routes` turns them into :class:`RouteSpec` objects for an input of a known channel
count, and :func:`route_params` gives a route's :class:`~vibsynth.dsp.follow.TrackerParams` from
the section's *live* values (:class:`LiveValues`: gain, gate and focus move over OSC/MIDI) and the
route's own overrides.

Without routes every output channel follows: input ``n`` drives channel ``n`` when the input has
as many channels as the engine (stereo in, two actuators), else every channel follows the mix
(mean) of all inputs.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibsynth.dsp.follow import Focus, Mode, TrackerParams, default_params
from vibsynth.dsp.follow.params import GAIN_DB_LIMITS
from vibsynth.errors import ConfigError
from vibsynth.settings.models_follow import Follow, FollowRoute

__all__ = ["LiveValues", "RouteSpec", "plan_routes", "route_params", "default_gate_db"]


@dataclass(frozen=True)
class LiveValues:
    """The section-wide values that live controls change: gain (dB), gate (dB or None), focus, range (dB)."""

    gain_db: float
    gate_db: float | None
    focus: Focus
    range_db: float = TrackerParams.range_db

    @classmethod
    def of(cls, follow: Follow) -> LiveValues:
        return cls(follow.gain_db, follow.gate_db, follow.focus, follow.range_db)


@dataclass(frozen=True)
class RouteSpec:
    """One route, resolved.

    Attributes
    ----------
    kind : {"channel", "source"}
    index : int
        0-based output channel or touch source.
    columns : tuple of int
        0-based input channels mixed (mean) into the route.
    route : FollowRoute
        The overrides (an all-default route when the section named none).
    """

    kind: str
    index: int
    columns: tuple[int, ...]
    route: FollowRoute

    @property
    def label(self) -> str:
        """``ch2`` or ``source3`` (1-based, as in OSC addresses and status keys)."""
        return f"{'ch' if self.kind == 'channel' else 'source'}{self.index + 1}"


def default_gate_db(mode: Mode) -> float:
    """The gate of a mode when ``follow.gate_db`` is null (audio -60 LUFS, vibration only silence)."""
    return default_params(mode).gate_db


def plan_routes(follow: Follow, channels: int, inputs: int) -> list[RouteSpec]:
    """The routes of ``follow`` for an engine of ``channels`` channels and an input of ``inputs``.

    Raises
    ------
    ConfigError
        A route names an input channel the input does not have, or a channel the engine lacks.
    """
    if not follow.routes:
        one_to_one = inputs == channels and inputs > 1
        return [
            RouteSpec("channel", c, (c,) if one_to_one else tuple(range(inputs)), FollowRoute(channel=c + 1))
            for c in range(channels)
        ]
    specs = []
    for i, route in enumerate(follow.routes):
        if route.inputs is not None and max(route.inputs) > inputs:
            raise ConfigError(
                f"follow.routes[{i}].inputs = {route.inputs}: the input has {inputs} channel"
                f"{'s' if inputs != 1 else ''} (allowed: 1..{inputs})"
            )
        columns = tuple(range(inputs)) if route.inputs is None else tuple(c - 1 for c in route.inputs)
        if route.channel is not None:
            if route.channel > channels:
                raise ConfigError(f"follow.routes[{i}].channel = {route.channel}: the engine has {channels}")
            specs.append(RouteSpec("channel", route.channel - 1, columns, route))
        else:
            assert route.source is not None  # the model requires one of them
            specs.append(RouteSpec("source", route.source - 1, columns, route))
    return specs


def route_params(follow: Follow, live: LiveValues, route: FollowRoute) -> TrackerParams:
    """A route's tracker parameters: its overrides, else the live values, else the section's."""
    mode: Mode = route.mode or follow.mode
    gate = route.gate_db if route.gate_db is not None else live.gate_db
    low, high = GAIN_DB_LIMITS
    return TrackerParams(
        mode=mode,
        focus=route.focus or live.focus,
        gain_db=min(max(live.gain_db + route.gain_db, low), high),
        gate_db=default_gate_db(mode) if gate is None else gate,
        range_db=live.range_db if route.range_db is None else route.range_db,
        attack_ms=follow.attack_ms if route.attack_ms is None else route.attack_ms,
        release_ms=follow.release_ms if route.release_ms is None else route.release_ms,
        transients=follow.transients if route.transients is None else route.transients,
    )
