"""What a page may ask over the WebSocket, validated at the edge, applied through the Controller.

Messages are JSON objects with a ``type`` (at most :data:`MAX_MESSAGE_BYTES`); channels are
1-based as everywhere a user sees them (OSC ``/ch/1``, status ``ch1``), absent or null = all.

=========  ==============================================  ==========================
type       fields                                          controller call
=========  ==============================================  ==========================
knob       ``channel``, ``name`` (intensity|balance),       ``set_knob``
           ``value``, optional ``glide_ms``
texture    ``channel``, ``intensity``, ``balance``          ``set_texture`` (the XY pad)
glide      ``channel``, ``value_ms``                        ``set_glide``
mute       ``channel``, ``value`` (true/false)              ``set_mute``
panic      (nothing)                                        ``panic``
preset     ``channel``, ``name``                            ``load_preset`` (audition)
learn      ``knob`` (intensity|balance)                     MIDI learn (control/midi)
watch      ``channel`` (one)                                the spectrum shown on that page
=========  ==============================================  ==========================

An optional ``id`` (a short string or an integer) is echoed in the ``ack`` or ``error``
answer. Knob moves over a page's rate budget are not lost: the newest per channel and knob
is applied when the budget allows (:class:`Throttle`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

from vibsynth.errors import ParameterError, VibsynthError

__all__ = [
    "MAX_MESSAGE_BYTES",
    "SOURCE",
    "MessageError",
    "parse_message",
    "Command",
    "Throttle",
    "apply_command",
    "ALWAYS",
]

#: Longest WebSocket message a page may send.
MAX_MESSAGE_BYTES = 4096
#: Source name of the studio's knob moves (KnobEvent.source, monitors).
SOURCE = "studio"
#: Knob moves that can wait for the budget (the newest per key is applied); the rest need it now.
COALESCED = frozenset({"knob", "texture", "glide"})
#: Messages never refused for the budget: a panic must silence the actuators whatever the page
#: sent before it. Bounded all the same: a panic's cost does not grow with anything a page sends.
ALWAYS = frozenset({"panic"})
KNOBS = ("intensity", "balance")


class MessageError(ParameterError):
    """A malformed message (not JSON, not an object, unknown type, missing or mistyped field)."""


@dataclass(frozen=True)
class Command:
    """A validated message: its type, 0-based channels (None = all), fields and reply id."""

    type: str
    channels: tuple[int, ...] | None
    fields: dict[str, Any]
    id: str | int | None = None

    @property
    def key(self) -> Hashable:
        """Coalescing key: a later command with the same key makes this one pointless."""
        name = self.fields.get("name") if self.type == "knob" else None
        return (self.type, self.channels, name)


def _number(data: dict[str, Any], key: str) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MessageError(f"{key} must be a finite number, got {_show(value)}")
    return float(value)


def _show(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else str(value)
    return text if len(text) <= 40 else text[:39] + "…"


def _channels(data: dict[str, Any], count: int, *, one: bool = False) -> tuple[int, ...] | None:
    value = data.get("channel")
    if value is None and not one:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= count:
        raise MessageError(
            f"channel must be an integer 1..{count}{'' if one else ' or null (all)'}, got {_show(value)}"
        )
    return (value - 1,)


def parse_message(text: str | bytes, channels: int) -> Command:
    """Validate one WebSocket message.

    Parameters
    ----------
    text : str or bytes
        The message as received.
    channels : int
        The engine's channel count.

    Raises
    ------
    MessageError
        Over :data:`MAX_MESSAGE_BYTES`, not a JSON object, unknown type, bad field.
    """
    if len(text) > MAX_MESSAGE_BYTES:
        raise MessageError(f"message of {len(text)} bytes is over the limit of {MAX_MESSAGE_BYTES}")
    try:
        data = json.loads(text)
    except (ValueError, UnicodeDecodeError):
        raise MessageError("not JSON") from None
    if not isinstance(data, dict):
        raise MessageError("a message must be a JSON object with a type")
    ident = data.get("id")
    if ident is not None and not (
        (isinstance(ident, int) and not isinstance(ident, bool) and abs(ident) < 2**53)
        or (isinstance(ident, str) and len(ident) <= 64)
    ):
        raise MessageError("id must be an integer or a string of up to 64 characters")
    kind = data.get("type")
    fields: dict[str, Any] = {}
    chans: tuple[int, ...] | None = None
    if kind == "knob":
        chans = _channels(data, channels)
        name = data.get("name")
        if name not in KNOBS:
            raise MessageError(f"name must be intensity or balance, got {_show(name)}")
        fields = {"name": name, "value": _number(data, "value")}
        if data.get("glide_ms") is not None:
            fields["glide_s"] = _number(data, "glide_ms") / 1000.0
    elif kind == "texture":
        chans = _channels(data, channels)
        fields = {"intensity": _number(data, "intensity"), "balance": _number(data, "balance")}
    elif kind == "glide":
        chans = _channels(data, channels)
        fields = {"seconds": _number(data, "value_ms") / 1000.0}
    elif kind == "mute":
        chans = _channels(data, channels)
        value = data.get("value")
        if not isinstance(value, bool):
            raise MessageError(f"value must be true or false, got {_show(value)}")
        fields = {"muted": value}
    elif kind == "panic":
        pass
    elif kind == "preset":
        chans = _channels(data, channels)
        name = data.get("name")
        if not isinstance(name, str) or not 1 <= len(name) <= 64:
            raise MessageError(f"name must be a preset name, got {_show(name)}")
        fields = {"name": name}
    elif kind == "learn":
        knob = data.get("knob")
        if knob not in KNOBS:
            raise MessageError(f"knob must be intensity or balance, got {_show(knob)}")
        fields = {"knob": knob}
    elif kind == "watch":
        chans = _channels(data, channels, one=True)
    else:
        raise MessageError(
            f"unknown message type {_show(kind)}; known: knob, texture, glide, mute, panic, preset, learn, watch"
        )
    return Command(str(kind), chans, fields, ident)


def apply_command(controller: Any, command: Command, *, learn: Callable[[str], bool] | None = None) -> None:
    """Carry out a validated command (``watch`` is the caller's business).

    Raises
    ------
    VibsynthError
        What the controller refuses (a value out of range, an unknown preset), or MIDI learn
        without a running MIDI input.
    """
    kind, chans, f = command.type, command.channels, command.fields
    if kind == "knob":
        controller.set_knob(f["name"], f["value"], channels=chans, glide_s=f.get("glide_s"), source=SOURCE)
    elif kind == "texture":
        controller.set_texture(f["intensity"], f["balance"], channels=chans, source=SOURCE)
    elif kind == "glide":
        controller.set_glide(f["seconds"], channels=chans, source=SOURCE)
    elif kind == "mute":
        controller.set_mute(f["muted"], channels=chans, source=SOURCE)
    elif kind == "panic":
        controller.panic(source=SOURCE)
    elif kind == "preset":
        controller.load_preset(f["name"], channels=chans, source=SOURCE)
    elif kind == "learn":
        if learn is None or learn(f["knob"]) is False:
            raise VibsynthError("MIDI learn unavailable (no MIDI input is running)")


@dataclass
class Throttle:
    """A page's message budget: ``rate`` per second (burst ``burst``).

    Knob moves over budget wait in :attr:`deferred` (the newest per key) until the budget
    refills; other messages over budget are refused. Bounded: one entry per key.
    """

    rate: float = 2000.0
    burst: float = 400.0
    clock: Callable[[], float] = time.monotonic
    tokens: float = field(init=False)
    last: float = field(init=False)
    deferred: dict[Hashable, Command] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.tokens = self.burst
        self.last = self.clock()

    def take(self) -> bool:
        """Spend one message of budget; False when there is none."""
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False

    def wait_s(self) -> float:
        """Time until one message of budget is back."""
        return max(0.0, (1.0 - self.tokens) / self.rate)
