"""What an OSC method table is: the argument checks its methods share and the registration contract.

The handler (:class:`~vibsynth.control.osc.handler.OscHandler`) has its own methods (knobs,
queries, subscriptions) and takes further tables through ``register``: the touch sources
(:mod:`~vibsynth.control.osc.sources`) and the clips (:mod:`~vibsynth.control.osc.clips`) are
registered by the server's wiring (:mod:`~vibsynth.control.osc.tables`). A table needs no
handler: it gets the controller and the prefix, raises a :class:`~vibsynth.errors.VibsynthError`
for a bad message (the handler replies and counts it) and sends its answers to the peer.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

from vibsynth.control.controller import check_finite
from vibsynth.control.osc.codec import Message
from vibsynth.control.osc.workers import PeerLike
from vibsynth.errors import ParameterError

__all__ = ["OscArgumentError", "Method", "Getter", "MethodTable", "arg_count", "number", "string", "flag"]

_NUMERIC = frozenset("ifdh")

#: A method: ``(message, channels or sources (0-based; None = all), peer, at_frame or None)``.
Method = Callable[[Message, "tuple[int, ...] | None", PeerLike, "int | None"], None]
#: An answer to ``get NAME``: ``(peer, channels (0-based; None = all))``.
Getter = Callable[[PeerLike, "tuple[int, ...] | None"], None]


class MethodTable(Protocol):
    """Methods an OSC handler takes on (:meth:`~vibsynth.control.osc.handler.OscHandler.register`)."""

    def methods(self) -> Mapping[str, Method]:
        """Method name (as routed by :class:`~vibsynth.control.osc.address.AddressSpace`) -> method."""
        ...

    def getters(self) -> Mapping[str, Getter]:
        """Setting name -> its answer to ``/vibsynth/get NAME`` (``/vibsynth/ch/{n}/get NAME``)."""
        ...


class OscArgumentError(ParameterError):
    """Wrong number or type of OSC arguments."""


def arg_count(msg: Message, allowed: Sequence[int], what: str) -> None:
    """Refuse a message whose argument count is not one of ``allowed`` (``what``: the arguments expected)."""
    if len(msg.args) not in allowed:
        want = " or ".join(str(n) for n in allowed)
        raise OscArgumentError(f"expects {want} argument(s) ({what}), got {len(msg.args)}")


def number(msg: Message, index: int, name: str) -> float:
    """Argument ``index`` as a finite number (OSC type i, f, d or h)."""
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag not in _NUMERIC:
        raise OscArgumentError(f"{name} must be a number (OSC type i, f, d or h), got type {tag!r}")
    return check_finite(name, msg.args[index])


def string(msg: Message, index: int, name: str) -> str:
    """Argument ``index`` as a string (OSC type s or S)."""
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag not in "sS":
        raise OscArgumentError(f"{name} must be a string (OSC type s), got type {tag!r}")
    return str(msg.args[index])


def flag(msg: Message, index: int, name: str) -> bool:
    """Argument ``index`` as a switch: OSC T/F, or a number 0 or 1."""
    tag = msg.types[index] if index < len(msg.types) else "?"
    if tag in "TF":
        return bool(msg.args[index])
    value = number(msg, index, name)
    if value not in (0.0, 1.0):
        raise ParameterError(f"{name} must be 0 or 1, got {value:g}")
    return value == 1.0
