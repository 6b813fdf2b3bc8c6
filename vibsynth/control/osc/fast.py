"""The OSC fast path: which addresses the compiled UDP receive loop handles on its own.

:mod:`vibsynth.control.osc._fast` receives every UDP datagram with the GIL released.
Messages of the shapes a VR app or controller sends every frame (``intensity f``,
``balance f``, ``texture ff`` at an exact address, global or per channel, with finite
values inside the live ranges) go from the socket straight into the engine's command
ring; everything else reaches :class:`~vibsynth.control.osc.handler.OscHandler` in arrival order.
The controller learns of fast-path moves through :meth:`Controller.record` before the
handler sees the next Python batch and at most 20 ms later otherwise, so ``get``,
``/status`` and ``/notify`` stay right. While a monitor reads the input tap, the loop also
keeps each datagram it took, as received, and they are published then (source ``osc-fast``,
with the sender and the time of arrival), described as the handler describes the others: a
global ``/vibsynth/intensity f 0.3`` is one line with that address, whatever channels it moved.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Callable, Iterable
from functools import partial
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.osc import _fast as _oscfast
from vibsynth.control.osc.address import AddressSpace
from vibsynth.control.osc.codec import Message, decode_packet
from vibsynth.control.osc.monitor import describe_message, describe_sender
from vibsynth.control.tap import InputTap

__all__ = ["FAST_METHODS", "fast_table", "allow_networks", "make_receiver"]

FAST_METHODS = {"intensity": _oscfast.M_INTENSITY, "balance": _oscfast.M_BALANCE, "texture": _oscfast.M_TEXTURE}
"""Methods the compiled loop decodes itself (when the arguments are valid)."""

SOURCE = "osc"
#: The monitor's name for a message the fast path took (the handler's are ``osc``).
SEEN_SOURCE = "osc-fast"
#: A datagram the fast path took while a monitor read the tap: (datagram, (host, port), arrival).
Seen = tuple[bytes, tuple[str, int], float]


def fast_table(space: AddressSpace) -> list[tuple[bytes, int, int]]:
    """``(address, method code, channel or -1)`` for every fast-path address of ``space``."""
    table = []
    for address in space.addresses:
        (route,) = space.match(address)
        code = FAST_METHODS.get(route.method)
        if code is not None:
            table.append((address.encode("ascii"), code, -1 if route.channel is None else route.channel))
    return table


def allow_networks(allow: Iterable[Any] | None) -> list[tuple[int, bytes, int]] | None:
    """The allow list as ``(IP version, packed network, prefix length)`` (None = everyone).

    Accepts IP strings, CIDR strings and :mod:`ipaddress` addresses or networks.
    """
    if allow is None:
        return None
    out: list[tuple[int, bytes, int]] = []
    for entry in allow:
        net = ipaddress.ip_network(entry if not isinstance(entry, str) else entry.split("%")[0], strict=False)
        out.append((net.version, net.network_address.packed, net.prefixlen))
    return out


def make_receiver(
    fd: int,
    on_slow: Callable[[list[tuple[bytes, tuple[str, int]]]], None],
    allow: Iterable[Any] | None,
    *,
    controller: Controller | None = None,
    space: AddressSpace | None = None,
    tap: InputTap | None = None,
) -> Any:
    """A compiled receive loop on socket ``fd`` (its ``run()`` blocks until ``stop()``).

    With a controller whose engine has a compiled core, and an address space, the fast path
    is on; otherwise every datagram goes to ``on_slow``. The messages the fast path takes are
    published on ``tap`` as received (at most 20 ms after their arrival, stamped with it)
    while someone reads it.
    """
    core = getattr(getattr(controller, "engine", None), "_core", None)
    if controller is None or space is None or core is None:
        return _oscfast.Receiver(fd, None, [], 0.0, 0.0, on_slow, lambda *state: None, allow_networks(allow))
    limits = controller.limits

    def on_state(updates: list[tuple[str, int, float]], last_seq: int, seen: list[Seen]) -> None:
        controller.record(updates, last_seq, source=SOURCE)
        if tap is not None:
            for data, address, when in seen:
                tap.publish(SEEN_SOURCE, partial(_describe, data, address), at=when)

    return _oscfast.Receiver(
        fd,
        core,
        fast_table(space),
        limits.balance_min,
        limits.balance_max,
        on_slow,
        on_state,
        allow_networks(allow),
        None if tap is None else tap.flag,
    )


def _describe(data: bytes, address: tuple[str, int]) -> str:
    msg = decode_packet(data)  # the fast path took it: one well-formed message
    assert isinstance(msg, Message)
    return describe_message(msg, describe_sender(address))
