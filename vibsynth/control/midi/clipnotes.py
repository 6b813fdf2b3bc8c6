"""MIDI notes that play haptic clips (the ``midi_clips:`` config section; docs/clips.md, "Triggering from MIDI").

A note (or a note range) of the map plays its clip on the note's actuator channels when it
is pressed, with a gain from the velocity, ``(velocity / 127) ** velocity_curve`` times the
entry's gain, and (``note_off: stop``, the default) stops it when it is released, gliding
back to the knob state over the release time. While the sustain pedal (CC 64 >= 64) is
down, note-offs wait until it comes up. Notes of the map never reach the gate-mode texture
logic of :class:`~vibsynth.control.midi.mapper.MidiMapper`; other notes do.

No stuck clips: all-notes-off / all-sound-off (CC 120, 123-127), a system reset and a
vanished port stop the clips the notes started (a one-shot entry, ``note_off: ignore``, is
left to play to its end when the port vanishes). A note-off stops only the clip *its* note
started: if another note or an OSC play took the channel over since, nothing is stopped.

Pure with respect to ports: the mapper calls it from the MIDI input thread (or the offline
renderer). The player is the controller's running :class:`~vibsynth.control.clips.player.ClipPlayer`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import mido

from vibsynth.control.clips import player_of
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.clips.timeline import ClipTimeline
from vibsynth.errors import VibsynthError

__all__ = ["CC_SUSTAIN", "NoteClip", "ClipNotes"]

CC_SUSTAIN = 64
SOURCE = "midi"


@dataclass(frozen=True)
class NoteClip:
    """One entry of the note map (0-based channels; ``actuators`` None = the MIDI channel map's)."""

    low: int
    high: int
    clip: str
    midi_channel: int | None
    actuators: tuple[int, ...] | None
    gain: float
    rate: float
    loops: int
    stop_on_note_off: bool
    release_s: float


@dataclass
class _Held:
    entry: NoteClip
    actuators: tuple[int, ...]
    timeline: ClipTimeline


class ClipNotes:
    """The note map of one MIDI input.

    Parameters
    ----------
    entries : iterable of NoteClip
    controller : Controller
        Its running clip player plays the clips (:func:`vibsynth.control.clips.player_of`).
    velocity_curve : float
    sustain : bool
        Honour the sustain pedal.
    player : callable, optional
        ``() -> ClipPlayer | None`` (default: the controller's running player).
    count_error : callable, optional
        ``count_error(kind)`` for refused plays (default: the controller's).
    """

    def __init__(
        self,
        entries: Iterable[NoteClip],
        controller: Any,
        *,
        velocity_curve: float = 1.0,
        sustain: bool = True,
        player: Callable[[], ClipPlayer | None] | None = None,
        count_error: Callable[[str], None] | None = None,
    ) -> None:
        self.controller = controller
        self.velocity_curve = float(velocity_curve)
        self.sustain_enabled = bool(sustain)
        self._player = player or (lambda: player_of(controller))
        self._count_error = count_error or controller.count_error
        self._by_note: dict[tuple[int | None, int], NoteClip] = {}
        for entry in entries:
            for note in range(entry.low, entry.high + 1):
                self._by_note.setdefault((entry.midi_channel, note), entry)
        self._held: dict[tuple[int, int], _Held] = {}  # (MIDI channel, note) -> what its note-on started
        self._pedal = [False] * 16
        self._sustained: list[set[int]] = [set() for _ in range(16)]  # notes released under the pedal
        self.counts: Counter[str] = Counter()
        self.last_error: str | None = None

    @classmethod
    def from_settings(
        cls, section: Any, controller: Any, *, player: Callable[[], ClipPlayer | None] | None = None
    ) -> ClipNotes | None:
        """From the ``midi_clips`` settings model (None when it maps no note); ``player`` as the class'."""
        if not section.notes:
            return None
        every = tuple(range(controller.channels))
        entries = []
        for item in section.notes:
            low, high = (item.note, item.note) if item.note is not None else tuple(item.notes)
            channels = item.channels
            actuators = None if channels is None else every if channels == "all" else tuple(c - 1 for c in channels)
            release_ms = section.release_ms if item.release_ms is None else item.release_ms
            entries.append(
                NoteClip(
                    low=int(low),
                    high=int(high),
                    clip=item.clip,
                    midi_channel=None if item.midi_channel is None else item.midi_channel - 1,
                    actuators=actuators,
                    gain=float(item.gain),
                    rate=float(item.rate),
                    loops=int(item.loops),
                    stop_on_note_off=item.note_off == "stop",
                    release_s=float(release_ms) / 1000.0,
                )
            )
        return cls(entries, controller, velocity_curve=section.velocity_curve, sustain=section.sustain, player=player)

    # ------------------------------------------------------------------ lookup
    def entry(self, midi_channel: int, note: int) -> NoteClip | None:
        """The entry of a note on a MIDI channel (an entry for that channel wins over one for any)."""
        return self._by_note.get((midi_channel, note)) or self._by_note.get((None, note))

    def _actuators(
        self, entry: NoteClip, channel_map: Mapping[int, tuple[int, ...]], midi_channel: int
    ) -> tuple[int, ...] | None:
        return entry.actuators if entry.actuators is not None else channel_map.get(midi_channel)

    # ------------------------------------------------------------------ notes
    def note_on(self, msg: mido.Message, channel_map: Mapping[int, tuple[int, ...]], at_frame: int | None) -> bool:
        """Play the note's clip; False when the note is not in the map (the mapper handles it)."""
        entry = self.entry(msg.channel, msg.note)
        if entry is None:
            return False
        acts = self._actuators(entry, channel_map, msg.channel)
        key = (msg.channel, msg.note)
        self._sustained[msg.channel].discard(msg.note)
        if acts is None:
            self._refuse("midi_unmapped_channel", f"MIDI channel {msg.channel + 1} maps to no actuator")
            return True
        player = self._player()
        if player is None:
            self._refuse("midi_no_clip_player", "clips are not available (no clip player is running)")
            return True
        gain = min(4.0, entry.gain * (msg.velocity / 127.0) ** self.velocity_curve)
        try:
            timeline = player.play(
                entry.clip,
                channels=acts,
                gain=gain,
                rate=entry.rate,
                loops=entry.loops,
                at_frame=at_frame,
                source=SOURCE,
            )
        except VibsynthError as exc:  # unknown clip, a full schedule: counted, never raised to the port
            self._refuse("midi_clip", str(exc))
            return True
        self.counts["played"] += 1
        self._held[key] = _Held(entry, acts, timeline)
        return True

    def note_off(self, msg: mido.Message, at_frame: int | None) -> bool:
        """Stop the clip its note-on started (now, or when the pedal comes up); False when not in the map."""
        entry = self.entry(msg.channel, msg.note)
        if entry is None:
            return False
        key = (msg.channel, msg.note)
        if not entry.stop_on_note_off:
            self._held.pop(key, None)
            return True
        if self.sustain_enabled and self._pedal[msg.channel]:
            if key in self._held:
                self._sustained[msg.channel].add(msg.note)
            return True
        self._stop(self._held.pop(key, None), at_frame)
        return True

    def pedal(self, midi_channel: int, value: int, at_frame: int | None) -> bool:
        """CC 64 on a MIDI channel; False when sustain is off (the mapper treats it as any CC)."""
        if not self.sustain_enabled:
            return False
        down = value >= 64
        self._pedal[midi_channel] = down
        if not down:
            for note in sorted(self._sustained[midi_channel]):
                self._stop(self._held.pop((midi_channel, note), None), at_frame)
            self._sustained[midi_channel].clear()
        return True

    # ------------------------------------------------------------------ no stuck clips
    def all_off(self, actuators: Iterable[int] | None, *, at_frame: int | None = None, release_s: float = 0.0) -> int:
        """Stop every clip a note started on ``actuators`` (None = all) and forget pedals; returns how many."""
        targets = None if actuators is None else set(actuators)
        stopped = 0
        for key, held in list(self._held.items()):
            if targets is None or targets.intersection(held.actuators):
                del self._held[key]
                self._sustained[key[0]].discard(key[1])
                stopped += self._stop(held, at_frame, release_s=release_s)
        if targets is None:
            self._pedal = [False] * 16
        return stopped

    def channel_off(self, midi_channel: int, *, at_frame: int | None = None, release_s: float = 0.0) -> int:
        """All notes off on one MIDI channel: stop the clips its notes started; returns how many."""
        stopped = 0
        for key, held in list(self._held.items()):
            if key[0] == midi_channel:
                del self._held[key]
                stopped += self._stop(held, at_frame, release_s=release_s)
        self._pedal[midi_channel] = False
        self._sustained[midi_channel].clear()
        return stopped

    def release_all(self) -> int:
        """The port vanished: every held note is released (one-shots play on); returns the clips stopped."""
        stopped = 0
        for key, held in list(self._held.items()):
            del self._held[key]
            if held.entry.stop_on_note_off:
                stopped += self._stop(held, None)
        self._pedal = [False] * 16
        self._sustained = [set() for _ in range(16)]
        return stopped

    # ------------------------------------------------------------------ helpers
    def _stop(self, held: _Held | None, at_frame: int | None, *, release_s: float | None = None) -> int:
        if held is None:
            return 0
        player = self._player()
        if player is None:
            return 0
        release = held.entry.release_s if release_s is None else release_s
        try:
            n = player.stop(
                channels=held.actuators, release_s=release, at_frame=at_frame, source=SOURCE, only=held.timeline
            )
        except VibsynthError as exc:
            self._refuse("midi_clip", str(exc))
            return 0
        self.counts["stopped"] += 1 if n else 0
        return 1 if n else 0

    def _refuse(self, kind: str, message: str) -> None:
        self.counts[kind] += 1
        self.last_error = message
        self._count_error(kind)
