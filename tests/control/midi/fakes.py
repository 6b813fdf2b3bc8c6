"""Test doubles shared by the MIDI tests."""

from __future__ import annotations


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
