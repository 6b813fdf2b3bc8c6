"""The OSC methods as OSCQuery nodes: TYPE, RANGE (from the typed settings), UNIT, DESCRIPTION, live VALUE.

:func:`method_nodes` walks the handler's address space and keeps the methods the handler
answers (:meth:`~vibsynth.control.osc.handler.OscHandler.method_names`): global and
per-channel knobs, glide, mute, preset, the touch sources (with a layout), clips (with a
player), follow (while it runs), status, get, sync, notify... Ranges come from the typed
settings (:func:`~vibsynth.settings.models.bounds_of`, the controller's live limits), preset
and clip names are RANGE ``VALS``. A global method's VALUE is channel 1's (``get`` answers the
global form when every channel agrees).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

from vibsynth.control import spatial
from vibsynth.control.clips import player_of
from vibsynth.control.controller import Controller
from vibsynth.control.follow import follower_of
from vibsynth.control.osc.follow import FOLLOW_ADDRESSES, GET_NAMES
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.oscquery.tree import Context, NodeSpec
from vibsynth.control.spatial.sources import SETTING_NAMES
from vibsynth.settings.cli_args import flag_choices
from vibsynth.settings.models import bounds_of
from vibsynth.settings.models_sources import MAX_SOURCES, POSITION_LIMIT_M, ROLLOFF_NAMES

__all__ = ["method_nodes", "reads", "knob_ranges"]

Names = Callable[[], list[str]]


def _span(low: float | None, high: float | None) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if low is not None:
        out["MIN"] = low
    if high is not None:
        out["MAX"] = high
    return out


def _bounds(key: str) -> dict[str, Any]:
    return _span(*bounds_of(key))


_SWITCH = {"MIN": 0, "MAX": 1}


def reads(controller: Controller) -> dict[str, Callable[[], Any]]:
    """The readings the method specs share (one each per request or push round)."""

    def sources() -> list[Any] | None:
        mixer = spatial.mixer_of(controller)
        if mixer is None:
            return None
        return list(mixer.read(lambda table, now: [table.view(i, now) for i in range(MAX_SOURCES)]))

    return {"state": controller.state, "sources": sources, "follower": lambda: follower_of(controller)}


def knob_ranges(controller: Controller) -> tuple[dict[str, Any], dict[str, Any]]:
    """The intensity and balance knobs' RANGE items: the typed settings' and the controller's live bounds."""
    limits = controller.limits
    return _bounds("knobs.initial_intensity"), _span(limits.balance_min, limits.balance_max)


def _channel_specs(controller: Controller, presets: Names) -> dict[str, Callable[[int], NodeSpec]]:
    """Knob method -> spec of channel ``c`` (0-based)."""
    intensity, balance = knob_ranges(controller)
    glide = _span(0.0, controller.limits.glide_max_s * 1000.0)

    def state(name: str, c: int, convert: Callable[[Any], Any] = float) -> Callable[[Context], list[Any]]:
        return lambda ctx: [convert(getattr(ctx["state"][c], name))]

    def specs(c: int) -> dict[str, NodeSpec]:
        return {
            "intensity": NodeSpec("f", "intensity 0..1 (0 = silent)", state("intensity", c), lambda ctx: [intensity]),
            "balance": NodeSpec(
                "f", "balance: low (-) to high (+) frequencies", state("balance", c), lambda ctx: [balance]
            ),
            "texture": NodeSpec(
                "ff",
                "intensity and balance at once",
                lambda ctx: [float(ctx["state"][c].intensity), float(ctx["state"][c].balance)],
                lambda ctx: [intensity, balance],
            ),
            "glide": NodeSpec(
                "f",
                "knob smoothing time",
                lambda ctx: [float(ctx["state"][c].glide_s) * 1000.0],
                lambda ctx: [glide],
                unit=("time.ms",),
            ),
            "mute": NodeSpec("i", "1 = muted (fades out), 0 = playing", state("muted", c, int), lambda ctx: [_SWITCH]),
            "preset": NodeSpec(
                "s",
                "load a preset (its intensity, balance and glide)",
                lambda ctx: [ctx["state"][c].preset or ""],
                lambda ctx: [{"VALS": presets()}],
            ),
        }

    return {name: partial(_pick, specs, name) for name in specs(0)}


def _pick(specs: Callable[[int], dict[str, NodeSpec]], name: str, index: int) -> NodeSpec:
    return specs(index)[name]


def _follow_spec(method: str, channel: int | None) -> NodeSpec:
    types, key = FOLLOW_ADDRESSES[method]
    if method == "follow":
        c = channel or 0
        return NodeSpec(
            types,
            "1 = this channel follows the input, 0 = its knobs",
            lambda ctx: None if ctx["follower"] is None else [int(ctx["follower"].is_on(c))],
            lambda ctx: [_SWITCH],
        )
    name = method.split("/", 1)[1]
    if types == "s":
        return NodeSpec(
            types,
            f"follow: {name}",
            lambda ctx: None if ctx["follower"] is None else [str(getattr(ctx["follower"], name))],
            lambda ctx: [{"VALS": list(flag_choices(key))}],
        )
    return NodeSpec(
        types,
        f"follow: {name} of the input level",
        lambda ctx: None if ctx["follower"] is None else [float(getattr(ctx["follower"], f"{name}_db"))],
        lambda ctx: [_bounds(key)],
        unit=("gain.db",),
    )


def _source_specs(controller: Controller, presets: Names, clips: Names) -> dict[str, Callable[[int], NodeSpec]]:
    """Source method -> spec of source ``k`` (0-based)."""
    pos = _span(-POSITION_LIMIT_M, POSITION_LIMIT_M)
    radius = _bounds("sources.radius")
    unit, balance = knob_ranges(controller)

    def view(k: int, read: Callable[[Any], list[Any]]) -> Callable[[Context], list[Any] | None]:
        return lambda ctx: None if ctx["sources"] is None else read(ctx["sources"][k])

    def specs(k: int) -> dict[str, NodeSpec]:
        return {
            "pos": NodeSpec(
                "fff",
                "move the source to x, y, z (metres on the layout)",
                view(k, lambda v: [float(x) for x in v.target]),
                lambda ctx: [pos, pos, pos],
                unit=("distance.m",) * 3,
            ),
            "texture": NodeSpec(
                "ff",
                "the source's intensity and balance",
                view(k, lambda v: [float(v.intensity), float(v.balance)]),
                lambda ctx: [unit, balance],
            ),
            "intensity": NodeSpec(
                "f", "the source's intensity", view(k, lambda v: [float(v.intensity)]), lambda ctx: [unit]
            ),
            "balance": NodeSpec(
                "f", "the source's balance", view(k, lambda v: [float(v.balance)]), lambda ctx: [balance]
            ),
            "preset": NodeSpec(
                "s",
                "the source's texture preset",
                view(k, lambda v: [v.preset or ""]),
                lambda ctx: [{"VALS": presets()}],
            ),
            "radius": NodeSpec(
                "f", "the source's radius", view(k, lambda v: [float(v.radius)]), lambda ctx: [radius], ("distance.m",)
            ),
            "rolloff": NodeSpec(
                "s", "roll-off law", view(k, lambda v: [str(v.rolloff)]), lambda ctx: [{"VALS": list(ROLLOFF_NAMES)}]
            ),
            "on": NodeSpec(
                "i", "1 = the source touches, 0 = off", view(k, lambda v: [int(v.on)]), lambda ctx: [_SWITCH]
            ),
            "speed": NodeSpec(
                "i", "1 = intensity from the source's speed", view(k, lambda v: [int(v.speed)]), lambda ctx: [_SWITCH]
            ),
            "get": NodeSpec(
                "s", "reply with a setting in setter form", range=lambda ctx: [{"VALS": list(SETTING_NAMES)}]
            ),
            "play": NodeSpec(
                "s",
                "play a clip on the source (then optional gain, rate, loops)",
                range=lambda ctx: [{"VALS": clips()}],
            ),
            "stop": NodeSpec("", "stop the source's clip (optional release in ms)"),
        }

    return {name: partial(_pick, specs, name) for name in specs(0)}


def method_nodes(handler: OscHandler, presets: Names, clips: Names) -> Callable[[], Mapping[str, NodeSpec]]:
    """``build()`` for :class:`~vibsynth.control.oscquery.tree.Tree`: the methods the handler answers now.

    Parameters
    ----------
    handler : OscHandler
        Its address space, registered methods and ``get`` names.
    presets, clips : callable
        The preset and clip names now (RANGE VALS).
    """
    controller = handler.controller
    knobs = _channel_specs(controller, presets)
    sources = _source_specs(controller, presets, clips)
    get_range: list[dict[str, Any] | None] = [{"VALS": list(handler.get_names())}]
    triggers: dict[str, NodeSpec] = {
        "panic": NodeSpec("", "mute every channel now (fade out)"),
        "speed": NodeSpec("f", "touch speed in mm/s -> texture (speed.curve)", unit=("speed.mm/s",)),
        "get": NodeSpec("s", "reply with a setting in setter form", range=lambda ctx: get_range),
        "status": NodeSpec("", "reply /status.reply with the server's counters"),
        "ping": NodeSpec("", "reply /pong with the same arguments"),
        "sync": NodeSpec("i", "reply /synced id once every earlier message is applied"),
        "notify": NodeSpec("i", "1 = push knob changes to this sender, 0 = stop", range=lambda ctx: [_SWITCH]),
        "learn": NodeSpec("s", "arm MIDI learn for a knob", range=lambda ctx: [{"VALS": ["intensity", "balance"]}]),
        "monitor": NodeSpec("i", "1 = stream the received messages (renew within 30 s), 0 = stop"),
        "play": NodeSpec("s", "play a clip (then optional gain, rate, loops)", range=lambda ctx: [{"VALS": clips()}]),
        "stop": NodeSpec("", "stop the clip (optional release in ms)"),
        "follow/get": NodeSpec("s", "reply with a follow setting", range=lambda ctx: [{"VALS": list(GET_NAMES)}]),
    }
    space = handler.space

    def build() -> dict[str, NodeSpec]:
        answered = handler.method_names()
        has_player = player_of(controller) is not None
        has_layout = spatial.mixer_of(controller) is not None
        follower = follower_of(controller)
        followed = set(follower.channels()) if follower is not None else set()
        out: dict[str, NodeSpec] = {}
        for address in space.addresses:
            route = space.match(address)[0]
            method, channel = route.method, route.channel
            if method not in answered:
                continue
            if method.startswith("source/"):
                if not has_layout or (method in ("source/play", "source/stop") and not has_player):
                    continue
                out[address] = sources[method[7:]](channel or 0)
            elif method in ("play", "stop") and not has_player:
                continue
            elif method in FOLLOW_ADDRESSES or method == "follow/get":
                if follower is None or (method == "follow" and channel not in followed):
                    continue
                out[address] = triggers[method] if method == "follow/get" else _follow_spec(method, channel)
            elif method in knobs:
                out[address] = knobs[method](0 if channel is None else channel)
            elif method in triggers:
                out[address] = triggers[method]
            else:  # a table registered later: listed, described by its name until it has a spec here
                out[address] = NodeSpec("", method)
        return out

    return build
