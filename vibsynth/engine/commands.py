"""Commands that control threads hand to the real-time engine.

Hand-off is a :class:`collections.deque` (append and popleft are atomic in CPython
and take no lock that Python code can hold), so a control thread never blocks
the audio thread and the audio thread never waits for a control thread. Commands
are immutable; producers allocate them, the audio thread only reads them.

Every submitted command gets a sequence number; the engine publishes the highest
number it has applied (``applied_seq``), which is how ``/sync`` knows that all
earlier commands took effect.

Channels: ``channels=None`` means every channel; otherwise a tuple of 0-based
channel indices. ``at_frame=None`` means "as soon as possible" (the next block);
otherwise the command applies at that stream position (frames since the stream
started; the engine applies it at the exact sample within a block).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = [
    "KnobName",
    "KNOB_NAMES",
    "SetKnob",
    "SetGlide",
    "SetMute",
    "Panic",
    "SetLayer",
    "CancelLayer",
    "LAYER_NAMES",
    "Command",
]

KnobName = Literal["intensity", "balance"]
KNOB_NAMES: tuple[KnobName, ...] = ("intensity", "balance")

#: Control layers that may drive a channel's knobs, by increasing priority (index = engine layer).
LAYER_NAMES: tuple[str, ...] = ("knobs", "follow", "sources", "clip")


@dataclass(frozen=True, slots=True)
class SetKnob:
    """Glide a knob to ``value`` (already validated and clamped by the controller).

    Attributes
    ----------
    name : {"intensity", "balance"}
    value : float
        Intensity 0..1 or balance in knob units.
    channels : tuple of int or None
    at_frame : int or None
    glide_s : float or None
        Glide for this move only (None: the channel's glide). 0 = jump.
    layer : int
        Index in :data:`LAYER_NAMES` of the control layer sending it; the move reaches only
        the channels that layer drives when it applies (0 = direct knob control).
    """

    name: KnobName
    value: float
    channels: tuple[int, ...] | None = None
    at_frame: int | None = None
    glide_s: float | None = None
    layer: int = 0


@dataclass(frozen=True, slots=True)
class SetLayer:
    """From ``at_frame`` on, control layer ``layer`` drives the channels' knobs (other layers' moves are ignored)."""

    layer: int
    channels: tuple[int, ...] | None = None
    at_frame: int | None = None


@dataclass(frozen=True, slots=True)
class CancelLayer:
    """Drop every command of control layer ``layer`` submitted before this one, on the channels (immediate)."""

    layer: int
    channels: tuple[int, ...] | None = None
    at_frame: None = None


@dataclass(frozen=True, slots=True)
class SetGlide:
    """Set the knob glide time (seconds; 0 = jump) of channels."""

    seconds: float
    channels: tuple[int, ...] | None = None
    at_frame: int | None = None


@dataclass(frozen=True, slots=True)
class SetMute:
    """Mute (fade out) or unmute (fade in) channels; knob values are kept."""

    muted: bool
    channels: tuple[int, ...] | None = None
    at_frame: int | None = None


@dataclass(frozen=True, slots=True)
class Panic:
    """Silence everything now: intensity targets to 0 with the short mute fade, pending scheduled commands dropped."""

    at_frame: None = None


Command = SetKnob | SetGlide | SetMute | Panic | SetLayer | CancelLayer
