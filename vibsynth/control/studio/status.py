"""The status panel: output, engine, OSC and MIDI counters, last errors, the studio's refusals.

The numbers are those of OSC ``/status`` (one definition: the running OSC server's
:meth:`~vibsynth.control.osc.handler.OscHandler.status_pairs`, or without OSC the same
parts from :mod:`vibsynth.control.status`), plus each MIDI input's counters and learn state.
Served at ``GET /api/status`` and pushed to open pages once a second.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from aiohttp import web

from vibsynth.control.midi import learn_hook
from vibsynth.control.status import channel_status, engine_status, output_status
from vibsynth.control.studio.periodic import WhilePagesOpen
from vibsynth.engine.supervisor import STREAMING

__all__ = ["PUSH_PERIOD_S", "StatusPanel", "midi_learn", "status_sources", "studio_status"]

#: How often open pages get the status.
PUSH_PERIOD_S = 1.0
#: Last control errors shown.
ERRORS_SHOWN = 8
#: Longest text shown for a device or an error.
TEXT_LIMIT = 400

Pairs = list[tuple[str, object]]


def _cut(text: str, size: int) -> str:
    return text if len(text) <= size else text[: size - 1] + "…"


def midi_learn(knob: str) -> bool:
    """Arm MIDI learn for ``knob`` on the running MIDI inputs; False when there is none."""
    hook = learn_hook()
    return bool(hook is not None and hook(knob))


def status_sources(servers: Sequence[Any]) -> list[Callable[[], Pairs]]:
    """The ``/status`` builders of the running control servers: the OSC server's reply, if OSC runs."""
    return [s.handler.status_pairs for s in servers if getattr(s, "name", "") == "osc" and hasattr(s, "handler")]


def _state_text(pairs: dict[str, object], output: Any) -> str:
    """``running``, ``null`` (no device), ``device lost``, ``recovering``, ``stopped``..."""
    state = str(pairs.get("output", "") or "")
    if output is not None and getattr(output, "name", "") == "null" and state == STREAMING:
        return "null"
    return "running" if state == STREAMING else state or "unknown"


def _midi_inputs(servers: Sequence[Any]) -> list[dict[str, Any]]:
    out = []
    for server in servers:
        mapper = getattr(server, "mapper", None)
        if getattr(server, "name", "") != "midi" or mapper is None:
            continue
        out.append(
            {
                "port": _cut(server.describe(), TEXT_LIMIT),
                "counts": dict(sorted(mapper.counts.items())),
                "learning": mapper.learning,
            }
        )
    return out


def studio_status(
    controller: Any,
    *,
    sources: Sequence[Callable[[], Pairs]] = (),
    servers: Sequence[Any] = (),
    refused: dict[str, int] | None = None,
    pages: int = 0,
) -> dict[str, Any]:
    """Everything the status panel shows, as JSON-ready data.

    Returns
    -------
    status : dict
        ``state`` (running / null / device lost / ...), ``state_reason``, ``device``,
        ``rate``, ``block_size``, ``underflows``, ``load``, ``load_peak``, ``osc`` (its
        counters, or None without OSC), ``midi`` (one entry per input), ``errors`` (the last
        control errors), ``studio`` (pages, refusals by reason) and ``pairs`` (every
        ``/status`` key).
    """
    if sources:
        pairs_list: Pairs = []
        for source in sources:
            pairs_list += source()
    else:
        pairs_list = (
            engine_status(controller)
            + [("errors", int(sum(controller.error_counts.values())))]
            + output_status(controller, controller.tap, _cut)
            + channel_status(controller)
        )
    pairs = dict(pairs_list)
    osc = None
    if sources:
        osc = {k: pairs.get(k) for k in ("messages", "fast_path", "packets", "malformed", "denied", "errors")}
    refusals = dict(refused or {})
    return {
        "type": "status",
        "state": _state_text(pairs, getattr(controller, "output", None)),
        "state_reason": pairs.get("output_reason", ""),
        "device": pairs.get("device", ""),
        "rate": pairs.get("rate"),
        "block_size": pairs.get("block_size"),
        "underflows": pairs.get("underflows"),
        "load": pairs.get("load"),
        "load_peak": pairs.get("load_peak"),
        "errors_total": pairs.get("errors"),
        "osc": osc,
        "midi": _midi_inputs(servers),
        "errors": [
            {"time": e.time, "source": e.source, "text": _cut(e.text, TEXT_LIMIT)}
            for e in controller.tap.last_errors()[-ERRORS_SHOWN:]
        ],
        "studio": {"pages": pages, "refused": refusals, "refused_total": sum(refusals.values())},
        "pairs": pairs,
    }


class StatusPanel:
    """``GET /api/status`` and a once-a-second push while pages are open.

    Parameters
    ----------
    server : StudioServer
    servers : sequence
        The running control servers (OSC, MIDI).
    """

    def __init__(self, server: Any, servers: Sequence[Any] = ()) -> None:
        self.server = server
        self.servers = tuple(servers)
        server.on_pages_changed(WhilePagesOpen(PUSH_PERIOD_S, self._push).pages_changed)

    def status(self) -> dict[str, Any]:
        server = self.server
        return studio_status(
            server.controller,
            sources=server.status_sources,
            servers=self.servers,
            refused=server.gate.refused() if server.gate is not None else {},
            pages=server.hub.page_count if server.hub is not None else 0,
        )

    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/api/status", self._get)

    async def _get(self, request: web.Request) -> web.StreamResponse:
        return web.json_response(self.status())

    def start(self) -> None:
        """Nothing to start: the push timer runs while pages are open."""

    def stop(self) -> None:
        """Nothing to stop: the push timer ends with the studio's loop."""

    def _push(self) -> None:
        self.server.post(("status",), self.status())
