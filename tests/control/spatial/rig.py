"""A mixer on a fake engine with a hand-driven clock: every step is the test's (no thread)."""

from __future__ import annotations

from vibsynth.control.controller import Controller, KnobLimits
from vibsynth.control.spatial.mixer import LAYER, SourceMixer
from vibsynth.control.spatial.sources import SourceDefaults, SourceTable
from vibsynth.dsp.spatial import TextureSpectra
from vibsynth.engine.commands import LAYER_NAMES, SetKnob
from vibsynth.settings.layouts import Layout
from vibsynth.settings.models_config import ChannelPosition

#: Four actuators on a line, 10 cm apart (channels 1..4), as in the e2e test.
LINE = {c + 1: ChannelPosition(x=0.1 * c, y=0.0) for c in range(4)}


class Clock:
    """Monotonic seconds the test moves by hand."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += seconds


_SPECTRA: dict[str, TextureSpectra] = {}


def spectra(basis) -> TextureSpectra:
    if "default" not in _SPECTRA:
        _SPECTRA["default"] = TextureSpectra(basis)
    return _SPECTRA["default"]


def make_mixer(controller: Controller, basis, *, positions=None, clock=None, **defaults) -> SourceMixer:
    """A mixer on ``positions`` (default :data:`LINE`) with linear roll-off and 10 cm radius unless told."""
    options = {"radius_m": 0.1, "rolloff": "linear", "glide_s": 0.02, "limits": KnobLimits()}
    options.update(defaults)
    table = SourceTable(SourceDefaults(**options), preset_resolver=controller.preset_resolver)
    return SourceMixer(
        controller,
        Layout(positions or LINE),
        spectra(basis),
        table,
        update_s=0.01,
        schedule_capacity=8,
        clock=clock or Clock(),
    )


#: The engine layer index of the sources layer (knobs < follow < sources < clip).
SOURCES_LAYER = LAYER_NAMES.index(LAYER)


def knob_moves(engine, name: str, layer: int = SOURCES_LAYER) -> dict[int, SetKnob]:
    """The last move of knob ``name`` on the ``sources`` layer per channel (0-based), from the fake engine."""
    out: dict[int, SetKnob] = {}
    for command in engine.commands:
        if isinstance(command, SetKnob) and command.name == name and command.layer == layer:
            for c in command.channels if command.channels is not None else range(engine.channels):
                out[c] = command
    return out
