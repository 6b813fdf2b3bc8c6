"""MIDI controllers bound to source coordinates (``sources.midi`` in the config; docs/vr.md).

A binding ``{source: 1, x: {cc: 20, range: [-0.1, 0.1]}, y: {cc: 21}}`` moves source 1's x
between -0.1 and 0.1 m as CC 20 goes from 0 to 127 (7-bit), on every MIDI channel or on the
one given. The MIDI mapper offers every controller change to :meth:`PositionControllers.handle`
before its knob bindings; the move goes to the running mixer like an OSC ``pos``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from vibsynth.control import spatial
from vibsynth.control.spatial.sources import SourceTable
from vibsynth.settings.models_sources import SourceMidi

__all__ = ["AxisBinding", "PositionControllers"]

_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class AxisBinding:
    """One controller moving one coordinate: 0-based ``source`` and ``axis`` (0 = x), metres at 0 and 127."""

    source: int
    axis: int
    channel: int | None  # 0-based MIDI channel, None = every channel
    low: float
    high: float

    def coordinate(self, value: int) -> float:
        """The coordinate for a 7-bit controller value (0..127)."""
        return self.low + (self.high - self.low) * min(max(value, 0), 127) / 127.0


class PositionControllers:
    """The ``sources.midi`` bindings of a controller's sources.

    Parameters
    ----------
    controller : Controller
        Whose mixer (:func:`vibsynth.control.spatial.mixer_of`) receives the moves.
    bindings : sequence of SourceMidi
    """

    def __init__(self, controller: Any, bindings: Sequence[SourceMidi]) -> None:
        self.controller = controller
        self.refused = 0
        self._by_cc: dict[int, list[AxisBinding]] = {}
        for item in bindings:
            for axis, name in enumerate(_AXES):
                cc = getattr(item, name)
                if cc is not None:
                    channel = None if cc.channel is None else cc.channel - 1
                    binding = AxisBinding(item.source - 1, axis, channel, cc.range[0], cc.range[1])
                    self._by_cc.setdefault(cc.cc, []).append(binding)

    @classmethod
    def from_settings(cls, bindings: Sequence[SourceMidi], controller: Any) -> PositionControllers | None:
        """The controllers of the typed ``sources.midi`` list, or None when it is empty."""
        return cls(controller, bindings) if bindings else None

    def handle(self, midi_channel: int, cc: int, value: int, at_frame: int | None = None) -> bool:
        """Move the coordinates bound to controller ``cc`` on ``midi_channel`` (0-based); False if none is.

        Without a running mixer (no layout) the move is counted (``midi_no_layout``) and dropped.
        """
        matches = [b for b in self._by_cc.get(cc, ()) if b.channel is None or b.channel == midi_channel]
        if not matches:
            return False
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            self.refused += 1
            self.controller.count_error("midi_no_layout")
            return True
        moves = [(b.source, b.axis, b.coordinate(value)) for b in matches]

        def update(table: SourceTable, t: float) -> None:
            for source, axis, coordinate in moves:
                table.set_axis(source, axis, coordinate, t)

        mixer.apply(update, at_frame=at_frame)
        return True
