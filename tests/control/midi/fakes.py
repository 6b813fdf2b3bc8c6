"""Test doubles shared by the MIDI tests."""

from __future__ import annotations

from typing import Any

import mido

from vibsynth.control.midi.bindings import MidiSettings
from vibsynth.settings.typed import settings_of


def midi_settings(data: Any, channels: int) -> MidiSettings:
    """The MIDI settings of a config dict (or typed settings) for ``channels`` actuators, as ``serve`` makes them."""
    if isinstance(data, dict):  # the config of a rig with that many actuators
        data = {**data, "audio": {**data.get("audio", {}), "channels": channels}}
    typed = settings_of(data)
    return MidiSettings.from_settings(typed.midi, channels, fade_ms=typed.knobs.mute_fade_ms)


class FakeEngine:
    """One channel, every command applied at once, the stream clock at frame 0."""

    channels, fs = 1, 48000.0

    def __init__(self) -> None:
        self.n = 0

    def submit(self, command) -> int:
        self.n += 1
        return self.n

    applied_seq = property(lambda self: self.n)
    frame_position = property(lambda self: 0)


class LoopPort(mido.ports.BaseIOPort):
    """A test port: what is sent comes back out of receive/iter_pending."""

    def _open(self, **kwargs) -> None:
        self._queue: list[mido.Message] = []

    def _send(self, msg: mido.Message) -> None:
        self._queue.append(msg)

    def _receive(self, block: bool = True):
        return self._queue.pop(0) if self._queue else None
