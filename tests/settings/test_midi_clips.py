"""The ``midi_clips:`` section: MIDI notes -> clips, typed and checked with file:line errors."""

from __future__ import annotations

import pytest

from vibsynth.errors import ConfigError
from vibsynth.settings.config import check_config_file


def test_note_map_entries_are_typed_with_defaults(tmp_path):
    path = tmp_path / "pads.yaml"
    path.write_text(
        "audio:\n  channels: 2\nmidi_clips:\n  velocity_curve: 2\n  notes:\n"
        "    - {note: 36, clip: impact, note_off: ignore}\n"
        "    - {notes: [48, 59], clip: rain, loops: 0, channels: [2], midi_channel: 10, release_ms: 80}\n"
        "    - {note: 48, clip: heartbeat}\n"  # any channel: channel 10's entry wins there
    )
    section = check_config_file(path).settings.midi_clips
    first, second, third = section.notes
    assert (first.note, first.clip, first.note_off, first.loops, first.gain, first.channels) == (
        36,
        "impact",
        "ignore",
        1,
        1.0,
        None,
    )
    assert (second.notes, second.loops, second.channels, second.midi_channel, second.release_ms) == (
        [48, 59],
        0,
        [2],
        10,
        80.0,
    )
    assert third.note == 48 and section.velocity_curve == 2.0 and section.release_ms == 30.0 and section.sustain


@pytest.mark.parametrize(
    ("entries", "line", "fragment"),
    [
        (
            "    - {note: 36, clip: a}\n    - {notes: [30, 40], clip: b}\n",
            5,
            "item 1: note 36 already plays item 0's clip",
        ),
        ("    - {note: 36, notes: [1, 2], clip: a}\n", 4, "item 0: give either note: N or notes: [low, high]"),
        ("    - {clip: a}\n", 4, "item 0: give either note: N or notes: [low, high]"),
        ("    - {note: 128, clip: a}\n", 4, "outside the allowed range [0, 127]"),
        ("    - {notes: [60, 50], clip: a}\n", 4, "must be [low, high] with low <= high"),
        ("    - {note: 1, clip: a, loops: -1}\n", 4, "outside the allowed range [0, 10000]"),
        ("    - {note: 1, clip: a, rate: 0}\n", 4, "outside the allowed range [0.05, 20]"),
        ("    - {note: 1, clip: a, gain: .nan}\n", 4, "must be finite"),
        ("    - {note: 1, clip: a, note_off: hold}\n", 4, "one of stop, ignore"),
        ("    - {note: 1, clip: a, channels: [2]}\n", 2, "actuator channel 2 but audio.channels = 1"),
        ("    - {note: 1, clip: a, velocity: 3}\n", 4, "unknown key"),
    ],
)
def test_bad_note_maps_name_the_line_and_the_rule(tmp_path, entries, line, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text("midi_clips:\n  notes:\n\n" + entries)
    with pytest.raises(ConfigError) as info:
        check_config_file(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: ") and "midi_clips.notes" in message, message
    assert fragment in message and "\n" not in message, message


def test_too_many_entries_are_refused(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text(
        "midi_clips:\n  notes:\n"
        + "".join(f"    - {{note: {n % 128}, clip: a, midi_channel: {1 + n // 128}}}\n" for n in range(257))
    )
    with pytest.raises(ConfigError, match="has 257 entries; at most 256"):
        check_config_file(path)
