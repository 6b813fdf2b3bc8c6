"""Test doubles shared by the OSC tests: an engine without audio and a reply-capturing peer."""

from __future__ import annotations

import threading

from vibsynth.control.controller import Controller, KnobLimits
from vibsynth.control.osc.codec import Bundle, Message, decode_packet, encode_message, iter_messages
from vibsynth.errors import PresetError


class FakeEngine:
    """Implements what Controller and the OSC handler use: submit, applied_seq, frame_position, channels, fs.

    ``auto_apply`` makes every command count as applied at once (like an engine that
    drains its queue immediately); otherwise :meth:`apply_all` does it.
    """

    def __init__(self, channels: int = 4, fs: float = 48000.0, auto_apply: bool = True) -> None:
        self.channels = channels
        self.fs = fs
        self.commands: list = []
        self.auto_apply = auto_apply
        self._seq = 0
        self._applied = 0
        self.frame = 480000
        self.lock = threading.Lock()

    def submit(self, command) -> int:
        with self.lock:
            self._seq += 1
            self.commands.append(command)
            if self.auto_apply:
                self._applied = self._seq
            return self._seq

    def apply_all(self) -> None:
        with self.lock:
            self._applied = self._seq

    @property
    def applied_seq(self) -> int:
        return self._applied

    @property
    def frame_position(self) -> int:
        return self.frame


class FakePreset:
    def __init__(self, name: str, intensity: float, balance: float, glide_ms: float | None = None) -> None:
        self.name, self.intensity, self.balance, self.glide_ms = name, intensity, balance, glide_ms


PRESETS = {"silk": FakePreset("silk", 0.3, -1.0, 50.0), "sand": FakePreset("sand", 0.7, 1.5)}


def resolve_preset(name: str) -> FakePreset:
    try:
        return PRESETS[name]
    except KeyError:
        raise PresetError(f"unknown preset {name!r}; known: {', '.join(PRESETS)}") from None


def make_controller(channels: int = 4, auto_apply: bool = True) -> Controller:
    return Controller(FakeEngine(channels, auto_apply=auto_apply), limits=KnobLimits(), preset_resolver=resolve_preset)


class FakePeer:
    """Captures replies; ``messages()`` decodes them (bundles flattened)."""

    def __init__(self, address: tuple[str, int] = ("127.0.0.1", 50000)) -> None:
        self.address = address
        self.sent: list[bytes] = []
        self.event = threading.Event()

    @property
    def key(self) -> tuple:
        return ("fake", self.address)

    def send(self, data: bytes) -> bool:
        self.sent.append(data)
        self.event.set()
        return True

    def messages(self) -> list[Message]:
        out = []
        for data in self.sent:
            packet = decode_packet(data)
            if isinstance(packet, Bundle):
                out.extend(m for m, _ in iter_messages(packet))
            else:
                out.append(packet)
        return out

    def errors(self) -> list[tuple]:
        return [m.args for m in self.messages() if m.address.endswith("/error")]

    def clear(self) -> None:
        self.sent.clear()
        self.event.clear()


def send(handler, peer: FakePeer, address: str, *args, types: str | None = None) -> None:
    """One OSC message from ``peer`` through ``handler`` (as raw bytes, like the socket's)."""
    handler.handle_packet(encode_message(address, args, types), peer)
