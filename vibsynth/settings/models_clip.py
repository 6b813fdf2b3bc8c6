"""Haptic clips, typed: a timeline of the two knobs (keyframes), short bursts on top (transients), loop points.

``docs/clips.md``'s key tables and ``vibsynth/data/schema/clip.schema.json`` are generated from
these models (``python scripts/gen_settings_docs.py``). A clip file holds :class:`ClipModel`'s
keys at the top level; its name is the file name without ``.yaml`` (the optional ``name`` key
must match it, as in presets).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import ConfigDict, Field, ValidationInfo, field_validator

from vibsynth.settings.fields import SettingsModel, ValueModel, problem, setting
from vibsynth.settings.models_clip_config import MAX_DECAY_MS
from vibsynth.settings.models_preset import MAX_DESCRIPTION, NAME_PATTERN, NAME_RULE, TAGS_ALLOWED, Tags
from vibsynth.settings.values import KNOB_BALANCE_LIMIT

__all__ = [
    "CLIP_VERSION",
    "CLIP_BALANCE_LIMIT",
    "MAX_DURATION_MS",
    "MAX_KEYFRAMES",
    "MAX_TRANSIENTS",
    "MAX_DECAY_MS",
    "INTERPOLATIONS",
    "Interpolation",
    "KeyframeModel",
    "TransientModel",
    "LoopModel",
    "ClipModel",
]

#: The clip schema version this vibsynth reads and writes.
CLIP_VERSION = 1
#: Longest clip: 10 minutes (a clip is an event or a short loop; a longer timeline is a recording).
MAX_DURATION_MS = 600_000.0
#: Most keyframes in one clip: one every 150 ms over 10 minutes, or a dense imported curve.
MAX_KEYFRAMES = 4096
#: Most transients in one clip (a 10-minute clip of footsteps at 2 per second is 1200).
MAX_TRANSIENTS = 2048

Interpolation = Literal["linear", "hold", "smooth"]
INTERPOLATIONS: tuple[str, ...] = ("linear", "hold", "smooth")


#: Clips may hold any balance a config's live range can reach (the widest ``knobs.balance_min/max``
#: allow); playback clamps to the live range.
CLIP_BALANCE_LIMIT = KNOB_BALANCE_LIMIT

_BALANCE_HELP = (
    "high/low balance (0 = the basis' mean spectrum, +1/-1 = 98th/2nd percentile); playback clamps to "
    "knobs.balance_min/max"
)


class KeyframeModel(ValueModel):
    """One point of the knob curve; ``interp`` shapes the segment from this keyframe to the next."""

    t_ms: float = setting(..., "time from the clip's start", unit="ms", ge=0, le=MAX_DURATION_MS)
    intensity: float = setting(..., "knob 0..1 at this time", ge=0, le=1)
    balance: float = setting(..., _BALANCE_HELP, unit="(knob units)", ge=-CLIP_BALANCE_LIMIT, le=CLIP_BALANCE_LIMIT)
    interp: Interpolation = setting(
        "linear",
        "shape of the segment that starts here: linear ramp, hold (a step at the next keyframe), "
        "smooth (cosine ease in and out)",
    )


class TransientModel(ValueModel):
    """A short burst on top of the curve: an onset at ``t_ms`` decaying over ``decay_ms``."""

    t_ms: float = setting(..., "onset time from the clip's start", unit="ms", ge=0, le=MAX_DURATION_MS)
    intensity: float = setting(..., "peak knob 0..1 of the burst", ge=0, le=1)
    balance: float = setting(..., _BALANCE_HELP, unit="(knob units)", ge=-CLIP_BALANCE_LIMIT, le=CLIP_BALANCE_LIMIT)
    decay_ms: float = setting(..., "time for the burst to die away", unit="ms", gt=0, le=MAX_DECAY_MS)


class LoopModel(ValueModel):
    """Loop points: playback that loops jumps from ``end_ms`` back to ``start_ms``."""

    start_ms: float = setting(..., "where each repetition starts", unit="ms", ge=0, le=MAX_DURATION_MS)
    end_ms: float = setting(..., "where playback jumps back to start_ms", unit="ms", gt=0, le=MAX_DURATION_MS)


def _after_end(what: str, value: float, duration: float) -> str:
    return f"{what} {value:g} ms is after the end of the clip (duration_ms = {duration:g})"


class ClipModel(SettingsModel):
    """A clip file (schema version 1): ``duration_ms`` and ``keyframes`` are required."""

    model_config = ConfigDict(title="vibsynth haptic clip")

    version: int = setting(CLIP_VERSION, "clip schema version", ge=CLIP_VERSION, le=CLIP_VERSION)
    name: str | None = setting(
        None,
        "the file name without .yaml (optional; if given it must match)",
        allowed=NAME_RULE,
        pattern=NAME_PATTERN,
    )
    description: str = setting("", "free text", allowed="text (a string)", max_length=MAX_DESCRIPTION)
    duration_ms: float = setting(..., "length of the clip", unit="ms", gt=0, le=MAX_DURATION_MS)
    keyframes: Annotated[list[KeyframeModel], Field(min_length=1, max_length=MAX_KEYFRAMES)] = setting(
        ...,
        "the knob curve: {t_ms, intensity, balance, interp} points, t_ms strictly increasing, within the "
        "duration; before the first and after the last the curve holds their values",
        allowed=f"a list of 1..{MAX_KEYFRAMES} keyframes {{t_ms: ms, intensity: 0..1, balance: knob units, "
        "interp: linear|hold|smooth}",
    )
    transients: Annotated[list[TransientModel], Field(max_length=MAX_TRANSIENTS)] = setting(
        [],
        "short bursts on top of the curve (impacts, steps, beats)",
        allowed=f"a list of up to {MAX_TRANSIENTS} transients {{t_ms: ms, intensity: 0..1, balance: knob units, "
        f"decay_ms: (0, {MAX_DECAY_MS:g}]}}",
    )
    loop: LoopModel | None = setting(
        None,
        "loop points {start_ms, end_ms} used when the clip plays looped; null = the whole clip",
        allowed="null or a mapping {start_ms: ms, end_ms: ms} with start_ms < end_ms <= duration_ms",
        title="Loop",
    )
    tags: Tags = setting([], "short words to find clips by", allowed=TAGS_ALLOWED)

    @field_validator("keyframes")
    @classmethod
    def _keyframes_in_order(cls, keyframes: list[KeyframeModel], info: ValidationInfo) -> list[KeyframeModel]:
        duration = info.data.get("duration_ms")
        previous: float | None = None
        for i, keyframe in enumerate(keyframes):
            if previous is not None and not keyframe.t_ms > previous:
                raise problem(
                    f"keyframe times must strictly increase (keyframes[{i - 1}].t_ms = {previous:g})", i, "t_ms"
                )
            if duration is not None and keyframe.t_ms > duration:
                raise problem(_after_end("keyframe at", keyframe.t_ms, duration), i, "t_ms")
            previous = keyframe.t_ms
        return keyframes

    @field_validator("transients")
    @classmethod
    def _transients_in_clip(cls, transients: list[TransientModel], info: ValidationInfo) -> list[TransientModel]:
        duration = info.data.get("duration_ms")
        if duration is not None:
            for i, transient in enumerate(transients):
                if transient.t_ms > duration:
                    raise problem(_after_end("transient at", transient.t_ms, duration), i, "t_ms")
        return transients

    @field_validator("loop")
    @classmethod
    def _loop_in_clip(cls, loop: LoopModel | None, info: ValidationInfo) -> LoopModel | None:
        if loop is None:
            return loop
        if not loop.start_ms < loop.end_ms:
            raise problem(f"must be after start_ms = {loop.start_ms:g} ms", "end_ms")
        duration = info.data.get("duration_ms")
        if duration is not None and loop.end_ms > duration:
            raise problem(_after_end("loop end", loop.end_ms, duration), "end_ms")
        return loop
