"""The ``midi_clips:`` config section, typed: MIDI notes that play haptic clips (a drum pad plays events).

Added to the root model (:class:`~vibsynth.settings.models_config.VibsynthConfig`) with one
line; ``docs/config.md``'s table of this section is generated from it, and docs/clips.md
("Triggering from MIDI") explains it.

Example::

    midi_clips:
      velocity_curve: 1.0     # gain = (velocity / 127) ** curve
      release_ms: 30          # a note-off stops the clip, gliding back over this
      notes:
        - {note: 36, clip: impact, note_off: ignore}        # a one-shot: plays to its end
        - {notes: [48, 59], clip: gravel-steps, loops: 0}   # loops while the key is held
        - {note: 60, clip: heartbeat, midi_channel: 10, channels: [2]}
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field

from vibsynth.limits import CLIP_GAIN_MAX, CLIP_LOOPS_MAX, CLIP_RATE_MAX, CLIP_RATE_MIN, GLIDE_MAX_MS
from vibsynth.settings.fields import Section, ValueModel, problem, setting
from vibsynth.settings.values import MIDI_CHANNELS

__all__ = ["MAX_NOTE_ENTRIES", "NOTE_MAX", "ClipNote", "MidiClips"]

NOTE_MAX = 127
#: Entries of ``midi_clips.notes`` (one per pad or key range; 128 notes x 16 channels at most mean anything).
MAX_NOTE_ENTRIES = 256

_Note = Annotated[int, Field(ge=0, le=NOTE_MAX)]


def _check_note_range(value: Any) -> Any:
    if isinstance(value, list) and len(value) == 2 and all(isinstance(v, int) for v in value) and value[0] > value[1]:
        raise problem(f"{value!r} must be [low, high] with low <= high")
    return value


class ClipNote(ValueModel):
    """One entry of ``midi_clips.notes``: a note (or a range of notes) that plays a clip."""

    note: _Note | None = setting(None, "MIDI note number 0..127 (60 = middle C); or give notes")
    notes: Annotated[list[_Note], Field(min_length=2, max_length=2), BeforeValidator(_check_note_range)] | None = (
        setting(None, "[low, high]: every note of the range plays the clip")
    )
    clip: str = setting(..., "the clip's name", min_length=1, max_length=128)
    midi_channel: Annotated[int, Field(ge=1, le=MIDI_CHANNELS)] | None = setting(
        None, "only this MIDI channel 1-16 (null = any)"
    )
    channels: Literal["all"] | Annotated[list[Annotated[int, Field(ge=1)]], Field(min_length=1)] | None = setting(
        None, "actuator channels (1-based list or 'all'); null = those of midi.channel_map"
    )
    gain: float = setting(1.0, "multiplies the velocity gain", ge=0, le=CLIP_GAIN_MAX)
    rate: float = setting(1.0, "playback rate (2 = twice as fast)", ge=CLIP_RATE_MIN, le=CLIP_RATE_MAX)
    loops: int = setting(1, "passes of the loop region; 0 = until the note is released", ge=0, le=CLIP_LOOPS_MAX)
    note_off: Literal["stop", "ignore"] = setting(
        "stop", "stop: a note-off stops the clip (after the sustain pedal); ignore: it plays to its end"
    )
    release_ms: Annotated[float, Field(ge=0, le=GLIDE_MAX_MS)] | None = setting(
        None, "glide back after a note-off; null = midi_clips.release_ms", unit="ms"
    )


_ENTRIES_ALLOWED = (
    "a list of {note: 0-127 or notes: [low, high], clip: name} with optional midi_channel (1-16), "
    "channels (1-based list or 'all'), gain, rate, loops, note_off (stop|ignore), release_ms"
)


def _check_entries(value: Any) -> Any:
    """Each entry names a note or a range (not both); no note plays two clips on the same MIDI channel.

    An entry for one MIDI channel may share notes with an entry for any channel: on that
    channel the specific entry wins.
    """
    if not isinstance(value, list):
        raise problem("must be a list of entries like {note: 36, clip: impact}")
    if len(value) > MAX_NOTE_ENTRIES:
        raise problem(f"has {len(value)} entries; at most {MAX_NOTE_ENTRIES}")
    taken: dict[tuple[int | None, int], int] = {}
    for i, entry in enumerate(value):
        if not isinstance(entry, dict):
            continue  # the model says what an entry must be
        if ("note" in entry) == ("notes" in entry):
            raise problem(f"item {i}: give either note: N or notes: [low, high]", i)
        span = [entry["note"]] * 2 if "note" in entry else entry["notes"]
        if not (isinstance(span, list) and len(span) == 2 and all(type(n) is int for n in span)):
            continue
        channel = entry.get("midi_channel")
        channel = channel if type(channel) is int else None
        for note in range(max(0, span[0]), min(NOTE_MAX, span[1]) + 1):
            other = taken.setdefault((channel, note), i)
            if other != i:
                where = "" if channel is None else f" on MIDI channel {channel}"
                raise problem(f"item {i}: note {note}{where} already plays item {other}'s clip", i)
    return value


class MidiClips(Section):
    """``midi_clips:``: MIDI notes that play haptic clips (docs/clips.md)."""

    notes: Annotated[list[ClipNote], BeforeValidator(_check_entries)] = setting(
        [], "notes (or ranges) -> clip, per entry", allowed=_ENTRIES_ALLOWED
    )
    velocity_curve: float = setting(1.0, "clip gain = (velocity/127) ** curve", ge=0.1, le=10)
    release_ms: float = setting(
        30.0, "glide back to the knob state after a note-off stops a clip", unit="ms", ge=0, le=GLIDE_MAX_MS
    )
    sustain: bool = setting(True, "the sustain pedal (CC 64) holds note-offs until it is released")
