"""Every model range that feeds the engine agrees with the engine (issue 26 item 9).

For each key below, the model's extreme values must be accepted by the model *and* by the
part of the engine (or the controller in front of it) the key reaches, through the same
mapping ``vibsynth serve`` uses (``Engine.from_settings``, ``BankSpec.from_settings``,
``Controller.for_knobs``...); just beyond them the model refuses, and so does the engine
where it has a limit of its own (``lab.gain_max = 20`` used to pass the model and fail
when the lab played a stimulus). A numeric key of these sections that is neither checked
here nor listed as not reaching the engine fails the test, so a new one cannot skip it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from vibsynth import limits
from vibsynth.control.clips.timeline import check_play_args
from vibsynth.control.controller import Controller
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.errors import ConfigError, ParameterError, VibsynthError
from vibsynth.formats.basis_file import default_basis
from vibsynth.research.lab.protocol import LabParameters
from vibsynth.settings.config import load_config
from vibsynth.settings.models_config import Audio, Bank, Knobs, VibsynthConfig
from vibsynth.settings.models_midi_clips import ClipNote
from vibsynth.settings.models_preset import PresetModel
from vibsynth.settings.validation import model_spec

#: Sections whose numeric keys reach the engine, a voice, the controller's glides or the clip player.
SECTIONS = ("audio", "bank", "knobs", "actuator", "lab", "midi", "midi_clips", "sources", "clips")
#: Numeric keys of those sections that do not reach the engine (why).
NOT_FED = {
    "audio.latency": "PortAudio's suggested latency, passed as it is",
    "midi.velocity_curve": "a curve of the mapper's, output clamped to the knob range",
    "midi.pitch_bend_range": "a balance offset the controller clamps to the live range",
    "midi.reconnect_interval_s": "the MIDI port's reconnect timer",
    "midi_clips.velocity_curve": "a curve of the clip notes, gain clamped by check_play_args",
    "sources.radius": "the mixer's geometry",
    "sources.update_ms": "the mixer thread's period",
    "sources.speed_window_ms": "the mixer's speed estimate",
    "sources.schedule_capacity": "the mixer's own schedule (control layer)",
    "clips.intensity_exponent": "an import mapping (a clip's keyframes are checked when loaded)",
    "clips.sharpness_0_balance": "an import mapping (a clip's keyframes are checked when loaded)",
    "clips.sharpness_half_balance": "an import mapping (a clip's keyframes are checked when loaded)",
    "clips.sharpness_1_balance": "an import mapping (a clip's keyframes are checked when loaded)",
    "clips.transient_decay_ms": "an import mapping (a clip's keyframes are checked when loaded)",
}

FS = 8000.0


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=FS, loop_seconds=0.5, levels=3, seed=1))


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    low_open: bool
    high_open: bool
    integer: bool

    def inside(self) -> list[float]:
        step = 1 if self.integer else 1e-9 * max(1.0, abs(self.low))
        return [self.low + step if self.low_open else self.low, self.high]

    def beyond(self) -> list[float]:
        step = 1 if self.integer else 1e-6 * max(1.0, abs(self.high))
        return [self.low if self.low_open else self.low - step, self.high + step]


def model_range(key: str, schema: dict[str, Any] | None = None) -> Range:
    schema = schema if schema is not None else model_spec(VibsynthConfig).leaves[key].schema
    for option in schema.get("anyOf", [schema]):
        if option.get("type") in ("integer", "number"):
            low_open, high_open = "exclusiveMinimum" in option, "exclusiveMaximum" in option
            low = option["exclusiveMinimum" if low_open else "minimum"]
            high = option["exclusiveMaximum" if high_open else "maximum"]
            return Range(low, high, low_open, high_open, option["type"] == "integer")
    raise KeyError(key)


# --------------------------------------------------------------------------- the engine side of each key
def _engine(bank, *, knobs: dict[str, Any] | None = None, audio: dict[str, Any] | None = None) -> Engine:
    """An engine made as serve makes it, from sections built without their model's checks."""
    k = Knobs.model_construct(**{**Knobs().model_dump(), **(knobs or {})})
    a = Audio.model_construct(**{**Audio().model_dump(), **(audio or {})})
    return Engine.from_settings(bank, k, a)


def _knob(field: str) -> Callable[[Any, float], object]:
    return lambda bank, value: _engine(bank, knobs={field: value})


def _bank_spec(field: str, fs: float = FS) -> Callable[[Any, float], object]:
    def make(bank, value):
        return BankSpec.from_settings(
            Bank.model_construct(**{**Bank().model_dump(), field: value}), fs, ActuatorResponse()
        )

    return make


def _glide(bank, value: float) -> object:
    """A glide of ``value`` ms asked of the controller (what MIDI releases, sources and clips ask)."""
    return Controller.for_knobs(_engine(bank), Knobs()).set_knob("intensity", 0.5, glide_s=value / 1000.0)


def _levels(bank, value: float) -> object:
    """A bank of that many levels (at the lowest rate and loop: small) through the engine."""
    spec = BankSpec(fs=2400.0, loop_seconds=0.5, levels=int(value))
    return Engine(build_bank(default_basis(), spec), max_block=1024)


def _voice_gain(bank, value: float) -> object:
    """A lab stimulus at its equalisation gain: a buffer voice."""
    return _engine(bank).play_buffer(np.zeros(64, np.float32), gain=value)


def _intensity(bank, value: float) -> object:
    return Controller.for_knobs(_engine(bank), Knobs()).set_knob("intensity", value)


def _lab(field: str, scale: float = 1.0) -> Callable[[Any, float], object]:
    return lambda bank, value: LabParameters(**{field: value * scale})


def _play_arg(index: int) -> Callable[[Any, float], object]:
    def check(bank, value):
        args = [1.0, 1.0, 1]
        args[index] = value
        return check_play_args(*args)

    return check


@dataclass(frozen=True)
class Fed:
    """How a key reaches the engine; ``bounded``: the engine refuses just beyond (low, high) too."""

    reach: Callable[[Any, float], object]
    bounded: tuple[bool, bool] = (False, False)
    context: dict[str, Any] | Callable[[float], dict[str, Any]] | None = None  # other keys a config needs there
    #: The extremes a config can reach, where a rule between keys narrows the range (low < high).
    inside: tuple[float, float] | None = None


#: A wider balance grid so the live range may reach its limits.
WIDE = {"bank.balance_min": -10.0, "bank.balance_max": 10.0}
FEEDS = {
    "audio.rate": Fed(
        lambda bank, v: BankSpec.from_settings(Bank(loop_seconds=0.5), v, ActuatorResponse()), (True, False)
    ),
    "audio.block_size": Fed(lambda bank, v: _engine(bank, audio={"block_size": int(v)})),
    "audio.channels": Fed(lambda bank, v: _engine(bank, audio={"channels": int(v)}), (True, True)),
    "bank.balance_min": Fed(_bank_spec("balance_min"), context={"knobs.balance_min": -0.0, "knobs.balance_max": 0.1}),
    "bank.balance_max": Fed(_bank_spec("balance_max"), context={"knobs.balance_min": -0.1, "knobs.balance_max": 0.0}),
    "bank.levels": Fed(_levels),
    "bank.loop_seconds": Fed(_bank_spec("loop_seconds", fs=2400.0)),  # at the lowest audio.rate
    "bank.seed": Fed(_bank_spec("seed")),
    "knobs.ceiling_db": Fed(_knob("ceiling_db")),
    "knobs.range_db": Fed(_knob("range_db"), (True, False)),
    "knobs.glide_ms": Fed(lambda bank, v: (_knob("glide_ms")(bank, v), _glide(bank, v)), (True, True)),
    "knobs.mute_fade_ms": Fed(_knob("mute_fade_ms"), (True, False)),
    "knobs.limiter_ceiling": Fed(_knob("limiter_ceiling"), (True, True)),
    "knobs.schedule_capacity": Fed(lambda bank, v: _knob("schedule_capacity")(bank, int(v)), (True, True)),
    "knobs.balance_min": Fed(_knob("balance_min"), context=WIDE),
    "knobs.balance_max": Fed(_knob("balance_max"), context=WIDE),
    "knobs.initial_intensity": Fed(_knob("initial_intensity"), (True, True)),
    "knobs.initial_balance": Fed(
        _knob("initial_balance"), context={**WIDE, "knobs.balance_min": -10, "knobs.balance_max": 10}
    ),
    "actuator.max_boost_db": Fed(
        lambda bank, v: ActuatorResponse.from_points([(100.0, -3.0)], max_boost_db=v), (True, False)
    ),
    "lab.gain_min": Fed(
        _voice_gain,
        (False, True),
        context={"lab.gain_max": limits.VOICE_GAIN_MAX},
        inside=(1e-9, limits.VOICE_GAIN_MAX * (1 - 1e-9)),  # below gain_max
    ),
    "lab.gain_max": Fed(_voice_gain, (False, True), context=lambda v: {"lab.gain_min": min(v / 2, 0.2)}),
    "lab.level": Fed(_intensity, (False, True)),
    "lab.stimulus_s": Fed(_lab("stimulus_s"), (True, True)),
    "lab.gap_ms": Fed(_lab("gap_s", 1e-3), (True, True)),
    "lab.familiarisation_pairs": Fed(lambda bank, v: LabParameters(familiarisation_pairs=int(v)), (True, True)),
    "midi.release_ms": Fed(_glide, (True, True)),
    "midi.attack_ms": Fed(_glide, (True, True)),
    "midi.cc_glide_max_ms": Fed(_glide, (True, True)),
    "midi_clips.release_ms": Fed(_glide, (True, True)),
    "sources.glide_ms": Fed(_glide, (True, True)),
}
#: ``midi_clips.notes[]`` entries: what a note asks of the clip player (``check_play_args``).
NOTE_FEEDS = {
    "gain": Fed(_play_arg(0), (True, True)),
    "rate": Fed(_play_arg(1), (True, True)),
    "loops": Fed(lambda bank, v: _play_arg(2)(bank, int(v)), (True, True)),
    "release_ms": Fed(_glide, (True, True)),
}


def _numeric_leaves() -> list[str]:
    spec = model_spec(VibsynthConfig)
    out = []
    for key, leaf in spec.leaves.items():
        if key.split(".")[0] in SECTIONS:
            try:
                model_range(key, leaf.schema)
            except KeyError:
                continue
            out.append(key)
    return out


def test_every_numeric_key_that_may_reach_the_engine_is_walked():
    unlisted = [k for k in _numeric_leaves() if k not in FEEDS and k not in NOT_FED]
    assert unlisted == [], "add each to FEEDS (how it reaches the engine) or NOT_FED (why it does not)"
    assert set(FEEDS) <= set(_numeric_leaves()) and set(NOT_FED) <= set(_numeric_leaves())


def _model_accepts(key: str, value: float, context: Any) -> bool:
    others = context(value) if callable(context) else context or {}
    try:
        load_config(overrides={**others, key: value}, env={}, user_file=False)
    except ConfigError:
        return False
    return True


@pytest.mark.parametrize("key", sorted(FEEDS))
def test_the_engine_takes_the_model_range(bank, key):
    fed, span = FEEDS[key], model_range(key)
    for value in fed.inside or span.inside():
        assert _model_accepts(key, value, fed.context), f"{key} = {value}: the model refuses its own extreme"
        fed.reach(bank, value)  # raises when the engine (or the controller before it) refuses
    for value, bounded in zip(span.beyond(), fed.bounded, strict=True):
        assert not _model_accepts(key, value, fed.context), f"{key} = {value}: beyond the range, accepted"
        if bounded:
            with pytest.raises((ParameterError, VibsynthError)):
                fed.reach(bank, value)


@pytest.mark.parametrize("field", sorted(NOTE_FEEDS))
def test_a_clip_note_takes_what_the_player_takes(bank, field):
    fed = NOTE_FEEDS[field]
    span = model_range(field, ClipNote.model_json_schema()["properties"][field])
    for value in span.inside():
        ClipNote.model_validate({"note": 60, "clip": "rain", field: value})
        fed.reach(bank, value)
    for value, bounded in zip(span.beyond(), fed.bounded, strict=True):
        with pytest.raises(ValueError):
            ClipNote.model_validate({"note": 60, "clip": "rain", field: value})
        if bounded:
            with pytest.raises((ParameterError, VibsynthError)):
                fed.reach(bank, value)


def test_a_lab_at_the_top_of_its_gain_range_plays(bank):
    """The finding: lab.gain_max = 20 passed the config and failed when a stimulus played."""
    with pytest.raises(ConfigError, match=r"lab.gain_max = 20: outside the allowed range \(0, 16\]"):
        load_config(overrides={"lab.gain_max": 20}, env={}, user_file=False)
    top = load_config(overrides={"lab.gain_max": limits.VOICE_GAIN_MAX}, env={}, user_file=False).settings.lab
    params = LabParameters.from_settings(top)
    engine = _engine(bank)
    engine.play_buffer(np.full(64, 0.01, np.float32), gain=params.gain_max)
    assert math.isclose(params.gain_max, 16.0) and np.abs(engine.render(128)).max() > 0


def test_a_preset_glide_is_one_the_controller_takes(bank):
    span = model_range("glide_ms", model_spec(PresetModel).leaves["glide_ms"].schema)
    for value in span.inside():
        _glide(bank, value)
    for value in span.beyond():
        with pytest.raises(ParameterError):
            _glide(bank, value)


def test_the_engine_refuses_the_ramps_the_compiled_core_would(bank):
    """``limits.ENGINE_RAMP_MAX_S`` is the core's own bound (``MAX_GLIDE_S``): the longest glide and mute
    fade both accept, and one beyond is the project's ParameterError from the Engine, never the core's
    ValueError."""
    top = limits.ENGINE_RAMP_MAX_S
    engine = Engine(bank, glide_s=top, mute_fade_s=top, max_block=128)
    assert engine.mute_fade_s == top
    for kwargs in ({"glide_s": math.nextafter(top, math.inf)}, {"mute_fade_s": top * 2}, {"glide_s": -1e-9}):
        with pytest.raises(ParameterError, match=r"must be in \[0, 3600\] s"):
            Engine(bank, max_block=128, **kwargs)
