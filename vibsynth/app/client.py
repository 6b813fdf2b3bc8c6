"""A Python client for a running ``vibsynth serve``: OSC over UDP, built on python-osc.

>>> import vibsynth                                                  # doctest: +SKIP
>>> with vibsynth.Client() as c:                                     # doctest: +SKIP
...     c.set_texture(0.6, -0.5, channel=2)
...     c.get("intensity", channel=2)
0.6000000238418579

The address space is the server's (docs/osc.md). Messages are built with python-osc's
builders (:mod:`pythonosc.osc_message_builder`, :mod:`pythonosc.osc_bundle_builder`) and
replies parsed with its parser (:mod:`pythonosc.osc_packet`); the server keeps its own
hardened codec, so the two sides are independent implementations of OSC 1.0.

Robustness: a datagram that is not valid OSC (or a reply of an unexpected shape) is
counted in :attr:`Client.stats` and ignored; it never raises. Bundle framing is checked
before python-osc sees a packet (element sizes, nesting depth), because python-osc's
parser trusts them. Each client has its own socket, so several clients (threads,
processes, notebooks) can talk to one server at once; replies are matched by their OSC
address.

This module imports nothing from the server (layers: app may import control, but a
client must work without the server's code and its compiled parts).
"""

from __future__ import annotations

import datetime as _dt
import itertools
import math
import numbers
import operator
import random
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Literal, overload

from pythonosc import osc_bundle_builder, osc_message, osc_message_builder, osc_packet
from pythonosc.parsing import osc_types

from vibsynth.errors import NoReplyError, ParameterError, ServerError, VibsynthError

__all__ = [
    "Client",
    "Bundle",
    "Reply",
    "ClientStats",
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "DEFAULT_PREFIX",
    "IMMEDIATELY",
    "encode_message",
    "encode_bundle",
    "parse_packet",
    "infer_types",
    "format_reply",
]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 9570
DEFAULT_PREFIX = "/vibsynth"

IMMEDIATELY = osc_bundle_builder.IMMEDIATELY
"""Bundle time meaning "now" (python-osc's ``IMMEDIATELY``; encoded as the OSC timetag 1)."""

#: Largest UDP payload (IPv4); the server reads at most 64 KiB.
MAX_DATAGRAM = 65507
#: Bundles nested deeper than this are refused (the server's limit too).
MAX_BUNDLE_DEPTH = 8
#: :meth:`Client.at` reads numbers below this as seconds from now, others as Unix time.
RELATIVE_LIMIT_S = 1e9

GETTABLE = ("intensity", "balance", "texture", "glide", "mute", "preset", "driver", "follow")
#: What :meth:`Client.follow_setting` reads (live Follow, docs/follow.md).
FOLLOW_SETTINGS = ("gain", "gate", "range", "focus")

_BUNDLE_TAG = b"#bundle\x00"
_MAX_PENDING_ERRORS = 256
# OSC 1.0 tags python-osc cannot build or parse, and a tag of the same wire format it can.
_ALIAS = {"S": "s", "c": "i", "I": "N"}
_PARSED = frozenset("ifdhsbrmtTFN[]") | frozenset(_ALIAS)
# tags whose values re-encode to the same bytes (checked after parsing)
_CANONICAL = frozenset("ifdhsSbcTFNI")


# ---------------------------------------------------------------------- wire format (python-osc)
@dataclass(frozen=True)
class Reply:
    """One OSC message received from the server.

    Attributes
    ----------
    address : str
    args : tuple
        Decoded arguments (python-osc's values: int, float, str, bytes, bool, None;
        ``math.inf`` for ``I``, a one-character str for ``c``).
    types : str
        Type tags without the leading comma.
    """

    address: str
    args: tuple[Any, ...]
    types: str


def infer_types(args: Sequence[object]) -> str:
    """OSC type tags for Python values: bool -> T/F, int -> i (h beyond 32 bits), float -> f, str -> s,
    bytes -> b, None -> N.

    Raises
    ------
    ParameterError
        For any other value.
    """
    tags = []
    for arg in args:
        if isinstance(arg, bool):
            tags.append("T" if arg else "F")
        elif isinstance(arg, numbers.Integral):
            tags.append("i" if -(2**31) <= int(arg) < 2**31 else "h")
        elif isinstance(arg, numbers.Real):
            tags.append("f")
        elif isinstance(arg, str):
            tags.append("s")
        elif isinstance(arg, (bytes, bytearray)):
            tags.append("b")
        elif arg is None:
            tags.append("N")
        else:
            raise ParameterError(f"cannot send {arg!r} as an OSC argument (int, float, str, bytes, bool or None)")
    return "".join(tags)


def _as_int(value: object, tag: str) -> int:
    if isinstance(value, numbers.Integral):
        return operator.index(value)
    if isinstance(value, numbers.Real) and float(value).is_integer():
        return int(float(value))
    raise ParameterError(f"OSC type {tag!r} needs an integer, got {value!r}")


def _check_address(address: object) -> str:
    if not isinstance(address, str) or not address.startswith("/") or "\x00" in address:
        raise ParameterError(f"an OSC address is a string starting with '/', got {address!r}")
    return address


def encode_message(address: str, args: Sequence[object] = (), types: str | None = None) -> bytes:
    """Encode one OSC message with python-osc's :class:`~pythonosc.osc_message_builder.OscMessageBuilder`.

    Parameters
    ----------
    address : str
        Address or address pattern (starts with ``/``).
    args : sequence
        Argument values.
    types : str, optional
        Type tags (a leading comma is ignored), e.g. ``"fi"``; inferred with :func:`infer_types`
        when None. Supported: ``i h f d s S c b t T F N I``. The data-less tags ``T F N I`` take
        a value from ``args`` only when ``args`` has one value per tag.

    Returns
    -------
    bytes

    Raises
    ------
    ParameterError
        Bad address, unsupported tag, or values that do not fit their tags.
    """
    _check_address(address)
    tags = infer_types(args) if types is None else types.lstrip(",")
    builder = osc_message_builder.OscMessageBuilder(address)
    values = iter(args)
    flags_take_values = len(args) == len(tags)
    retag: list[tuple[int, str]] = []
    try:
        for index, tag in enumerate(tags):
            if tag in "TFNI":
                if flags_take_values:
                    next(values)
                builder.add_arg(tag == "T", _ALIAS.get(tag, tag))
                if tag in _ALIAS:
                    retag.append((index, tag))
                continue
            value = next(values)
            if tag in "ih":
                builder.add_arg(_as_int(value, tag), tag)
            elif tag in "fd":
                if not isinstance(value, numbers.Real) or isinstance(value, bool):
                    raise ParameterError(f"OSC type {tag!r} needs a number, got {value!r}")
                builder.add_arg(float(value), tag)
            elif tag in "sS":
                builder.add_arg(str(value), "s")
            elif tag == "c":
                if not isinstance(value, str) or len(value) != 1:
                    raise ParameterError(f"OSC type 'c' needs one character, got {value!r}")
                builder.add_arg(ord(value), "i")
            elif tag == "b":
                if not isinstance(value, (bytes, bytearray)):
                    raise ParameterError(f"OSC type 'b' needs bytes, got {value!r}")
                if value:
                    builder.add_arg(bytes(value), "b")
                else:  # python-osc refuses an empty blob; its wire format is an int32 size of 0
                    builder.add_arg(0, "i")
            elif tag == "t":
                stamp = _as_int(value, tag)
                if not 0 <= stamp < 2**64:
                    raise ParameterError(f"an OSC timetag is a 64-bit unsigned integer, got {value!r}")
                builder.add_arg(stamp - 2**64 if stamp >= 2**63 else stamp, "h")
            else:
                raise ParameterError(f"cannot encode OSC type tag {tag!r} (supported: i h f d s S c b t T F N I)")
            if tag in "Scbt" and (tag != "b" or not value):
                retag.append((index, tag))
    except StopIteration:
        raise ParameterError(f"type tags {tags!r} need more arguments than the {len(args)} given") from None
    try:
        data = builder.build().dgram
    except (osc_message_builder.BuildError, ValueError, OverflowError) as exc:
        raise ParameterError(f"cannot encode {list(args)!r} as OSC types {tags!r}: {exc}") from None
    if retag:  # same wire format, the tag python-osc lacks
        buffer = bytearray(data)
        start = len(osc_types.write_string(address)) + 1  # after the ','
        for index, tag in retag:
            buffer[start + index] = ord(tag)
        data = bytes(buffer)
    return data


class _Encoded(osc_message.OscMessage):
    """An encoded message handed to python-osc's bundle builder as is (it only reads size and dgram)."""

    def __init__(self, dgram: bytes) -> None:
        self._dgram = dgram
        self._parameters: list[Any] = []


def encode_bundle(when: float, elements: Sequence[bytes]) -> bytes:
    """Encode a bundle with python-osc's :class:`~pythonosc.osc_bundle_builder.OscBundleBuilder`.

    Parameters
    ----------
    when : float
        Unix time (``time.time()`` scale) the bundle is for, or :data:`IMMEDIATELY` (0).
    elements : sequence of bytes
        Encoded messages or bundles.

    Returns
    -------
    bytes
    """
    builder = osc_bundle_builder.OscBundleBuilder(when)  # type: ignore[arg-type]  # it takes float seconds
    for element in elements:
        builder.add_content(_Encoded(bytes(element)))
    try:
        return builder.build().dgram
    except osc_bundle_builder.BuildError as exc:
        raise ParameterError(f"cannot encode a bundle for time {when!r}: {exc}") from None


def _walk(data: bytes, base: int, depth: int, found: list[tuple[int, int, str]]) -> bool:
    """Check the framing of a packet; list ``(start, end, tags)`` of its messages. False = malformed."""
    if not data or len(data) % 4:
        return False
    if data[:1] == b"/":
        try:
            _, index = osc_types.get_string(data, 0)
            tags = osc_types.get_string(data, index)[0] if index < len(data) else ","
        except Exception:  # noqa: BLE001 - python-osc leaks UnicodeDecodeError and others
            return False
        if not tags.startswith(",") or not set(tags[1:]) <= _PARSED:
            return False
        if set(tags) & set(_ALIAS) and set(tags) & set("[]"):
            return False
        found.append((base, base + len(data), tags[1:]))
        return True
    if data[:8] != _BUNDLE_TAG or depth >= MAX_BUNDLE_DEPTH or len(data) < 16:
        return False
    index = 16
    while index < len(data):
        if index + 4 > len(data):
            return False
        size = int.from_bytes(data[index : index + 4], "big", signed=True)
        index += 4
        if size <= 0 or size % 4 or index + size > len(data):
            return False
        if not _walk(data[index : index + size], base + index, depth + 1, found):
            return False
        index += size
    return True


def parse_packet(data: bytes) -> list[Reply] | None:
    """The messages of one datagram, parsed by python-osc (bundles flattened), or None if it is not valid OSC.

    Never raises: anything python-osc cannot parse, framing it would trust blindly (bundle
    element sizes, nesting beyond :data:`MAX_BUNDLE_DEPTH`) and non-UTF-8 strings give None.
    """
    found: list[tuple[int, int, str]] = []
    try:
        if not _walk(bytes(data), 0, 0, found):
            return None
        buffer = bytearray(data)
        for start, _end, tags in found:
            if set(tags) & set(_ALIAS):  # parse S/c/I as the tag of the same wire format, restore after
                tag_at = start + len(osc_types.write_string(osc_types.get_string(bytes(data), start)[0])) + 1
                for i, tag in enumerate(tags):
                    if tag in _ALIAS:
                        buffer[tag_at + i] = ord(_ALIAS[tag])
        patched = bytes(buffer)
        original = {patched[start:end]: (tags, bytes(data[start:end])) for start, end, tags in found}
        replies = []
        for timed in osc_packet.OscPacket(patched).messages:
            msg = timed.message
            tags, raw = original[msg.dgram]
            args = list(msg.params)
            if len(args) != len(tags) and not set(tags) & set("[]"):
                return None
            for i, tag in enumerate(tags):
                if tag == "c":
                    args[i] = chr(args[i])
                elif tag == "I":
                    args[i] = math.inf
            # python-osc reads leniently (a missing float reads 0.0, trailing bytes are ignored):
            # a message must be exactly what its values encode to
            if set(tags) <= _CANONICAL and encode_message(msg.address, args, tags) != raw:
                return None
            replies.append(Reply(msg.address, tuple(args), tags))
        return replies
    except Exception:  # noqa: BLE001 - garbage from the network must never escape as an exception
        return None


def format_reply(reply: Reply) -> str:
    """``/address types arg...`` like ``oscdump`` (strings quoted only when empty or with spaces)."""
    parts = [reply.address, reply.types or "-"]
    for arg in reply.args:
        if isinstance(arg, float):
            parts.append(repr(arg) if math.isfinite(arg) else str(arg))
        elif isinstance(arg, str):
            parts.append(repr(arg) if (" " in arg or not arg) else arg)
        else:
            parts.append(str(arg))
    return " ".join(parts)


# ---------------------------------------------------------------------- argument checks
def _number(name: str, value: object, low: float = -math.inf, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(f"{name} must be finite, got {number!r}")
    if not low <= number <= high:
        raise ParameterError(f"{name} {number:g} is outside the allowed range [{low:g}, {high:g}]")
    return number


def _channel(channel: object, *, optional: bool = True) -> int | None:
    if channel is None and optional:
        return None
    if isinstance(channel, bool) or not isinstance(channel, numbers.Integral) or int(channel) < 1:
        raise ParameterError(f"channel must be an integer >= 1 (channels are 1-based), got {channel!r}")
    return int(channel)


def _prefix(prefix: str) -> str:
    if not isinstance(prefix, str):
        raise ParameterError(f"prefix must be a string, got {prefix!r}")
    prefix = prefix.rstrip("/")
    if prefix and (not prefix.startswith("/") or any(c.isspace() or c in "*?[]{}#," for c in prefix)):
        raise ParameterError(f"prefix {prefix!r} must start with '/' and contain no spaces or pattern characters")
    return prefix


# ---------------------------------------------------------------------- knob commands (client and bundle)
class _Commands:
    """The knob setters, shared by :class:`Client` (sent at once) and :class:`Bundle` (collected)."""

    _prefix: str

    def _emit(self, data: bytes) -> None:  # pragma: no cover - implemented by subclasses
        raise NotImplementedError

    def _address(self, method: str, channel: int | None) -> str:
        channel = _channel(channel)
        return f"{self._prefix}/{method}" if channel is None else f"{self._prefix}/ch/{channel}/{method}"

    def set_intensity(self, value: float, channel: int | None = None) -> None:
        """Set the intensity knob (with the channel's glide).

        Parameters
        ----------
        value : float
            0..1; 0 is silence, (0, 1] spans ``knobs.range_db`` below the ceiling level.
        channel : int, optional
            1-based channel; None = every channel.

        Raises
        ------
        ParameterError
            Not a finite number in [0, 1], or a bad channel (checked before sending).
        """
        self._emit(encode_message(self._address("intensity", channel), (_number("intensity", value, 0.0, 1.0),), "f"))

    def set_balance(self, value: float, channel: int | None = None) -> None:
        """Set the high/low frequency balance knob (knob units: 0 = mean spectrum, +1/-1 = 98th/2nd percentile).

        Parameters
        ----------
        value : float
            Finite; the server accepts its live range (``knobs.balance_min..balance_max``, default -3.5..3.5).
        channel : int, optional
            1-based channel; None = every channel.
        """
        self._emit(encode_message(self._address("balance", channel), (_number("balance", value),), "f"))

    def set_texture(self, intensity: float, balance: float, channel: int | None = None) -> None:
        """Set intensity and balance at once (the server checks both before changing either).

        Parameters
        ----------
        intensity : float
            0..1.
        balance : float
        channel : int, optional
            1-based channel; None = every channel.
        """
        args = (_number("intensity", intensity, 0.0, 1.0), _number("balance", balance))
        self._emit(encode_message(self._address("texture", channel), args, "ff"))

    def set_glide(self, ms: float, channel: int | None = None) -> None:
        """Set the glide time of later knob moves.

        Parameters
        ----------
        ms : float
            Milliseconds, >= 0 (0 = jump; the server's maximum is ``knobs.glide_max``, 10 000 by default).
        channel : int, optional
            1-based channel; None = every channel.
        """
        self._emit(encode_message(self._address("glide", channel), (_number("glide (ms)", ms, 0.0),), "f"))

    def set_speed(self, mm_s: float, channel: int | None = None) -> None:
        """Set the intensity from a scanning speed through the server's speed curve (docs/osc.md).

        Parameters
        ----------
        mm_s : float
            Speed in mm/s, >= 0 (0 = silence).
        channel : int, optional
            1-based channel; None = every channel.
        """
        self._emit(encode_message(self._address("speed", channel), (_number("speed (mm/s)", mm_s, 0.0),), "f"))

    def mute(self, on: bool = True, channel: int | None = None) -> None:
        """Mute (with a short fade) or unmute; the knob values are kept.

        Parameters
        ----------
        on : bool
            True = mute, False = unmute.
        channel : int, optional
            1-based channel; None = every channel.
        """
        self._emit(encode_message(self._address("mute", channel), (1 if on else 0,), "i"))

    def unmute(self, channel: int | None = None) -> None:
        """Same as ``mute(False, channel)``."""
        self.mute(False, channel)

    def panic(self) -> None:
        """Silence every channel now (intensity 0, scheduled moves dropped); always immediate, even in a bundle."""
        self._emit(encode_message(f"{self._prefix}/panic"))

    def preset(self, name: str, channel: int | None = None) -> None:
        """Glide to a preset's knobs (with the preset's glide).

        Parameters
        ----------
        name : str
            Preset name (``vibsynth preset list``); an unknown name is refused by the server.
        channel : int, optional
            1-based channel; None = every channel.
        """
        if not isinstance(name, str) or not name:
            raise ParameterError(f"preset name must be a non-empty string, got {name!r}")
        self._emit(encode_message(self._address("preset", channel), (name,), "s"))

    def play_clip(
        self, name: str, channel: int | None = None, *, gain: float = 1.0, rate: float = 1.0, loops: int = 1
    ) -> None:
        """Play a haptic clip (docs/clips.md); in a timetagged bundle it starts at that exact sample.

        Parameters
        ----------
        name : str
            Clip name (``vibsynth clip list``); an unknown name is refused by the server.
        channel : int, optional
            1-based channel; None = every channel.
        gain : float
            Scales the clip's intensity, 0..4 (the result is clamped to 1).
        rate : float
            Playback rate, 0.05..20 (2 = twice as fast).
        loops : int
            Passes of the clip's loop region, 1..10000; 0 = until :meth:`stop_clip`.
        """
        if not isinstance(name, str) or not name:
            raise ParameterError(f"clip name must be a non-empty string, got {name!r}")
        if isinstance(loops, bool) or not isinstance(loops, int) or not 0 <= loops <= 10_000:
            raise ParameterError(f"loops must be an integer in [0, 10000] (0 = until stopped), got {loops!r}")
        args = (name, _number("gain", gain, 0.0, 4.0), _number("rate", rate, 0.05, 20.0), loops)
        self._emit(encode_message(self._address("play", channel), args, "sffi"))

    def stop_clip(self, channel: int | None = None, *, release_ms: float | None = None) -> None:
        """Stop the clip playing on a channel (None = every channel); it glides back to its knob state.

        Parameters
        ----------
        channel : int, optional
            1-based channel; None = every channel.
        release_ms : float, optional
            Glide back over this long (ms, >= 0); None = the channel's glide.
        """
        args = () if release_ms is None else (_number("release (ms)", release_ms, 0.0),)
        self._emit(encode_message(self._address("stop", channel), args, "f" * len(args)))

    def set_follow(self, on: bool = True, channel: int | None = None) -> None:
        """Follow the input on a channel (live Follow, docs/follow.md), or hand it back to its knobs.

        Parameters
        ----------
        on : bool
            True = the channel follows; False = its knobs play again.
        channel : int, optional
            1-based channel; None = every channel (the server refuses a channel no route follows into).
        """
        address = f"{self._prefix}/ch/*/follow" if channel is None else self._address("follow", channel)
        self._emit(encode_message(address, (1 if on else 0,), "i"))

    def set_follow_gain(self, db: float) -> None:
        """Live Follow's gain in dB, added to the tracked level (the server checks ``follow.gain_db``'s range)."""
        self._emit(encode_message(f"{self._prefix}/follow/gain", (_number("follow gain (dB)", db),), "f"))

    def set_follow_gate(self, db: float) -> None:
        """Live Follow's gate in dB: below this input level the output is silent (``follow.gate_db``'s range)."""
        self._emit(encode_message(f"{self._prefix}/follow/gate", (_number("follow gate (dB)", db),), "f"))

    def set_follow_range(self, db: float) -> None:
        """Live Follow's input range in dB, spread over the intensity knob (``follow.range_db``'s range)."""
        self._emit(encode_message(f"{self._prefix}/follow/range", (_number("follow range (dB)", db),), "f"))

    def set_follow_focus(self, focus: str) -> None:
        """Live Follow's focus in audio mode: ``all``, ``effects``, ``bass`` or ``beat`` (docs/follow.md)."""
        if not isinstance(focus, str) or not focus:
            raise ParameterError(f"focus must be a non-empty string, got {focus!r}")
        self._emit(encode_message(f"{self._prefix}/follow/focus", (focus,), "s"))


# ---------------------------------------------------------------------- bundles
class Bundle(_Commands):
    """Commands collected into one OSC bundle, sent when the ``with`` block ends without an exception.

    Made by :meth:`Client.bundle` (applied at once, together) and :meth:`Client.at` (timetagged:
    the server applies every command at the exact sample of that time). It has the same
    setters as :class:`Client` and :meth:`add` for any other message. Only knob, glide, mute,
    preset and clip play/stop messages are scheduled by the server; ``panic`` and queries act at once.

    Attributes
    ----------
    when : float
        Unix time of the bundle, or :data:`IMMEDIATELY` (0).
    messages : list of bytes
        The encoded messages so far.
    """

    def __init__(self, client: Client, when: float) -> None:
        self._client = client
        self._prefix = client.prefix
        self.when = when
        self.messages: list[bytes] = []
        self._sent = False

    def _emit(self, data: bytes) -> None:
        if self._sent:
            raise RuntimeError("this bundle was already sent; start a new one with client.bundle() or client.at()")
        self.messages.append(data)

    def add(self, address: str, *args: object, types: str | None = None) -> None:
        """Add any message (see :func:`encode_message` for ``types``)."""
        self._emit(encode_message(address, args, types))

    def encode(self) -> bytes:
        """The bundle as one OSC packet."""
        return encode_bundle(self.when, self.messages)

    def send(self) -> None:
        """Send the bundle now (done by the ``with`` block; only once)."""
        if self._sent:
            raise RuntimeError("this bundle was already sent")
        data = self.encode()
        self._sent = True
        self._client.send_packet(data)

    def __enter__(self) -> Bundle:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None and not self._sent:
            self.send()


# ---------------------------------------------------------------------- the client
@dataclass
class ClientStats:
    """Counters of a :class:`Client`.

    Attributes
    ----------
    sent : int
        Packets sent.
    received : int
        Datagrams received.
    malformed : int
        Datagrams that were not valid OSC, or replies of an unexpected shape (ignored).
    ignored : int
        Valid messages nobody was waiting for (e.g. a late reply), dropped.
    errors : int
        ``/error`` replies received.
    """

    sent: int = 0
    received: int = 0
    malformed: int = 0
    ignored: int = 0
    errors: int = 0


class Client(_Commands):
    """Talk to a running ``vibsynth serve`` over OSC/UDP.

    Setters (:meth:`set_intensity`, :meth:`set_texture`, ...) send one datagram and return
    at once, like a VR app streaming knob moves every frame; they check their arguments
    first (:class:`~vibsynth.errors.ParameterError`). The server refuses values outside its
    live ranges with an error reply: :meth:`sync` waits until the engine applied everything
    sent before and raises :class:`~vibsynth.errors.ServerError` for every refusal since the
    last check. Queries (:meth:`get`, :meth:`status`, :meth:`ping`) wait for their reply.

    Parameters
    ----------
    host : str
        Server host name or address.
    port : int
        Server UDP port (``osc.port``).
    timeout : float
        Default seconds to wait for a reply.
    prefix : str
        The server's address prefix (``osc.prefix``); ``""`` for none.
    local_port : int
        Local UDP port to send from and receive replies on (0 = any free port).

    Raises
    ------
    ParameterError
        A bad port or timeout, a host that does not resolve, or a local port that cannot be bound.

    Notes
    -----
    One socket per client; replies come back to it (unless the server sets ``osc.reply_port``,
    then queries time out). A client may be shared between threads: queries take turns.
    """

    _host: str
    _port: int
    _timeout: float
    _target: Any
    _sock: socket.socket
    _lock: threading.RLock
    _ids: Iterator[int]
    _pending: deque[tuple[str, str]]
    stats: ClientStats

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        *,
        timeout: float = 1.0,
        prefix: str = DEFAULT_PREFIX,
        local_port: int = 0,
    ) -> None:
        if isinstance(port, bool) or not isinstance(port, numbers.Integral) or not 1 <= int(port) <= 65535:
            raise ParameterError(f"port must be an integer in 1..65535, got {port!r}")
        if isinstance(local_port, bool) or not isinstance(local_port, numbers.Integral):
            raise ParameterError(f"local port must be an integer in 0..65535, got {local_port!r}")
        if not 0 <= int(local_port) <= 65535:
            raise ParameterError(f"local port must be in 0..65535, got {local_port!r}")
        self._timeout = self._check_timeout(timeout)
        self._prefix = _prefix(prefix)
        self._host = str(host)
        self._port = int(port)
        try:
            found = socket.getaddrinfo(self._host, self._port, type=socket.SOCK_DGRAM)
        except (OSError, UnicodeError) as exc:
            raise ParameterError(f"cannot resolve host {host!r}: {getattr(exc, 'strerror', None) or exc}") from None
        # IPv4 first: "localhost" may list ::1 first while the server listens on 127.0.0.1
        family, _, _, _, sockaddr = min(found, key=lambda info: info[0] != socket.AF_INET)
        self._target = sockaddr
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind(("::" if family == socket.AF_INET6 else "0.0.0.0", int(local_port)))
        except OSError as exc:
            self._sock.close()
            raise ParameterError(f"cannot use local UDP port {local_port}: {exc.strerror or exc}") from None
        self._lock = threading.RLock()
        self._ids = itertools.count(random.randrange(1, 2**30))
        self._pending: deque[tuple[str, str]] = deque(maxlen=_MAX_PENDING_ERRORS)
        self.stats = ClientStats()

    # ------------------------------------------------------------------ basics
    @staticmethod
    def _check_timeout(timeout: object) -> float:
        return _number("timeout", timeout, 0.0)

    @property
    def host(self) -> str:
        """Server host, as given."""
        return self._host

    @property
    def port(self) -> int:
        """Server UDP port."""
        return self._port

    @property
    def prefix(self) -> str:
        """Address prefix (``/vibsynth`` by default)."""
        return self._prefix

    @property
    def timeout(self) -> float:
        """Default seconds to wait for a reply."""
        return self._timeout

    @property
    def local_address(self) -> tuple[str, int]:
        """``(address, port)`` the client's socket is bound to (replies come back there)."""
        address = self._sock.getsockname()
        return str(address[0]), int(address[1])

    @classmethod
    def discover(
        cls,
        name: str | None = None,
        *,
        seconds: float = 2.0,
        interfaces: Sequence[str] | None = None,
        timeout: float = 1.0,
    ) -> Client:
        """A client of a vibsynth server found on the network (mDNS ``_oscjson._tcp`` + OSCQuery HOST_INFO).

        Parameters
        ----------
        name : str, optional
            Part of the service name to pick (default: the first server whose name holds "vibsynth").
        seconds : float
            How long to listen for services.
        interfaces : sequence of str, optional
            IP addresses to browse on (default: every interface).
        timeout : float
            The client's reply timeout.

        Raises
        ------
        VibsynthError
            No matching service answered within ``seconds``.
        """
        from vibsynth.control.oscquery.discovery import discover

        wanted = (name or "vibsynth").lower()
        found = [f for f in discover(seconds, interfaces=interfaces) if wanted in f.name.lower() and f.osc_port]
        if not found:
            raise VibsynthError(f"no OSCQuery service named like {wanted!r} found in {seconds:g} s (is serve running?)")
        service = found[0]
        assert service.osc_host is not None and service.osc_port is not None
        return cls(service.osc_host, service.osc_port, timeout=timeout)

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._sock.fileno() < 0

    def close(self) -> None:
        """Close the socket (idempotent)."""
        self._sock.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<vibsynth.Client {self._host}:{self._port} prefix={self._prefix!r} {state}>"

    # ------------------------------------------------------------------ sending
    def send_packet(self, data: bytes) -> None:
        """Send one encoded OSC packet (message or bundle).

        Raises
        ------
        ParameterError
            Larger than a UDP datagram.
        OSError
            The operating system refused to send (e.g. no route to the host).
        """
        if len(data) > MAX_DATAGRAM:
            raise ParameterError(f"OSC packet of {len(data)} bytes is larger than a UDP datagram ({MAX_DATAGRAM})")
        if self.closed:
            raise ParameterError("the client is closed")
        self._sock.sendto(data, self._target)
        self.stats.sent += 1

    def _emit(self, data: bytes) -> None:
        self.send_packet(data)

    def send(self, address: str, *args: object, types: str | None = None) -> None:
        """Send any message, e.g. ``client.send("/vibsynth/ch/*/balance", 1.0)``.

        Parameters
        ----------
        address : str
            Address or OSC 1.0 pattern.
        *args
            Arguments; types are inferred (:func:`infer_types`) unless ``types`` is given.
        types : str, optional
            Type tags, e.g. ``"fi"``.
        """
        self.send_packet(encode_message(address, args, types))

    def bundle(self) -> Bundle:
        """A bundle applied at once: ``with client.bundle() as b: b.set_intensity(0.5, 1); b.set_intensity(0.2, 2)``.

        The server applies its commands together, in order (the same audio block).
        """
        return Bundle(self, IMMEDIATELY)

    def at(self, when: float | _dt.datetime) -> Bundle:
        """A timetagged bundle: its commands take effect at that exact sample.

        Parameters
        ----------
        when : float or datetime.datetime
            Seconds from now (a number below 10**9, >= 0) or a Unix time (``time.time()``
            scale), or a datetime (naive = local time). Taken when ``at`` is called. The
            server refuses times more than ``osc.schedule_horizon_s`` (10 s) ahead; a time
            in the past applies at once. Server and client clocks must agree (NTP).

        Returns
        -------
        Bundle
            Use it in a ``with`` block; it is sent when the block ends.
        """
        if isinstance(when, _dt.datetime):
            return Bundle(self, when.timestamp())
        seconds = _number("bundle time", when)
        if seconds < RELATIVE_LIMIT_S:
            if seconds < 0:
                raise ParameterError(f"a bundle time from now must be >= 0 s, got {seconds:g}")
            seconds += time.time()
        return Bundle(self, seconds)

    # ------------------------------------------------------------------ receiving
    def receive(self, timeout: float | None = None) -> list[Reply]:
        """Messages of the next valid datagram to arrive within ``timeout`` s ([] if none).

        For subscriptions (``client.send("/vibsynth/notify", 1)``) and anything the query
        methods do not cover. Invalid datagrams are counted and skipped.
        """
        deadline = time.monotonic() + (self._timeout if timeout is None else self._check_timeout(timeout))
        with self._lock:
            while True:
                replies = self._next(deadline)
                if replies is None:
                    return []
                if replies:
                    return replies

    def _next(self, deadline: float) -> list[Reply] | None:
        """The next datagram's messages ([] for garbage), None once ``deadline`` passed."""
        remaining = deadline - time.monotonic()
        try:
            if remaining <= 0:
                self._sock.setblocking(False)
            else:
                self._sock.settimeout(remaining)
            data = self._sock.recv(65536)
        except (TimeoutError, BlockingIOError):
            return None
        except OSError:  # e.g. an ICMP error reported on the socket (Windows): not a reply
            if time.monotonic() >= deadline:
                return None
            time.sleep(min(0.001, max(0.0, remaining)))
            return []
        self.stats.received += 1
        replies = parse_packet(data)
        if replies is None:
            self.stats.malformed += 1
            return []
        return replies

    def _error_of(self, reply: Reply) -> tuple[str, str] | None:
        if reply.address != f"{self._prefix}/error":
            return None
        if len(reply.args) >= 2 and isinstance(reply.args[0], str) and isinstance(reply.args[1], str):
            return reply.args[0], reply.args[1]
        return None

    def _sort(self, reply: Reply, request: str | None) -> tuple[str, str] | None:
        """Book an unmatched reply; return an error about ``request``."""
        error = self._error_of(reply)
        if error is None:
            if reply.address == f"{self._prefix}/error":
                self.stats.malformed += 1
            else:
                self.stats.ignored += 1
            return None
        self.stats.errors += 1
        if request is not None and error[0] == request:
            return error
        self._pending.append(error)
        return None

    def _drain(self) -> None:
        """Take what is already queued (late replies, errors of earlier sends) before a new request."""
        while (replies := self._next(0.0)) is not None:
            for reply in replies:
                self._sort(reply, None)

    def request(
        self,
        address: str,
        *args: object,
        types: str | None = None,
        match: Callable[[Reply], bool],
        timeout: float | None = None,
    ) -> Reply:
        """Send a message and wait for the first reply accepted by ``match``.

        Parameters
        ----------
        address : str
        *args
            Arguments (``types`` as in :meth:`send`).
        match : callable
            ``match(reply) -> bool``.
        timeout : float, optional
            Default: the client's.

        Returns
        -------
        Reply

        Raises
        ------
        ServerError
            The server answered ``/error`` about ``address``.
        NoReplyError
            Nothing matching arrived in time.
        """
        wait = self._timeout if timeout is None else self._check_timeout(timeout)
        data = encode_message(address, args, types)
        with self._lock:
            self._drain()
            self.send_packet(data)
            deadline = time.monotonic() + wait
            while (replies := self._next(deadline)) is not None:
                for reply in replies:
                    try:
                        if match(reply):
                            return reply
                    except Exception:  # noqa: BLE001 - a reply of an unexpected shape is garbage
                        self.stats.malformed += 1
                        continue
                    error = self._sort(reply, address)
                    if error is not None:
                        raise ServerError(*error)
        raise NoReplyError(self._host, self._port, wait, address)

    # ------------------------------------------------------------------ queries
    @overload
    def get(
        self, what: Literal["intensity", "balance", "glide"], channel: int = 1, timeout: float | None = None
    ) -> float: ...
    @overload
    def get(self, what: Literal["mute", "follow"], channel: int = 1, timeout: float | None = None) -> bool: ...
    @overload
    def get(self, what: Literal["preset"], channel: int = 1, timeout: float | None = None) -> str | None: ...
    @overload
    def get(self, what: Literal["driver"], channel: int = 1, timeout: float | None = None) -> str: ...
    @overload
    def get(self, what: Literal["texture"], channel: int = 1, timeout: float | None = None) -> tuple[float, float]: ...
    @overload
    def get(
        self, what: str, channel: int = 1, timeout: float | None = None
    ) -> float | bool | str | tuple[float, float] | None: ...

    def get(
        self, what: str, channel: int = 1, timeout: float | None = None
    ) -> float | bool | str | tuple[float, float] | None:
        """A channel's current target value (what was last requested, including scheduled moves).

        Parameters
        ----------
        what : {"intensity", "balance", "texture", "glide", "mute", "preset", "driver", "follow"}
        channel : int
            1-based channel.
        timeout : float, optional
            Seconds to wait (default: the client's).

        Returns
        -------
        float, bool, str, tuple or None
            intensity, balance: float; glide: float (ms); mute: bool; preset: str, or None when
            no preset is applied; texture: ``(intensity, balance)``; driver: the layer the channel
            plays, ``"knobs"``, ``"follow"``, ``"sources"`` or ``"clip"``; follow: whether the channel
            follows the input (live Follow). Floats come as OSC float32 (``0.6`` reads ``0.6000000238418579``).

        Raises
        ------
        ParameterError
            Unknown ``what`` or a bad channel.
        ServerError
            The server refused (e.g. no such channel).
        NoReplyError
            No answer within the timeout.
        """
        if what not in GETTABLE:
            raise ParameterError(f"unknown setting {what!r}; known: {', '.join(GETTABLE)}")
        n = _channel(channel, optional=False)
        base = f"{self._prefix}/ch/{n}"
        want = f"{base}/{what}"

        def numeric(value: object) -> bool:
            return isinstance(value, (int, float)) and not isinstance(value, bool)

        def match(reply: Reply) -> bool:
            if reply.address != want:
                return False
            args = reply.args
            if what == "texture":
                ok = len(args) == 2 and numeric(args[0]) and numeric(args[1])
            elif what in ("mute", "follow"):
                ok = len(args) == 1 and (numeric(args[0]) or isinstance(args[0], bool))
            elif what in ("preset", "driver"):
                ok = len(args) == 1 and isinstance(args[0], str)
            else:
                ok = len(args) == 1 and numeric(args[0])
            if not ok:
                self.stats.malformed += 1
            return ok

        reply = self.request(f"{base}/get", what, types="s", match=match, timeout=timeout)
        value = reply.args
        if what == "texture":
            return float(value[0]), float(value[1])
        if what in ("mute", "follow"):
            return bool(value[0])
        if what == "preset":
            return value[0] or None
        if what == "driver":
            return str(value[0])
        return float(value[0])

    def playing_clip(self, channel: int = 1, timeout: float | None = None) -> tuple[str, float, int] | None:
        """What clip plays on a channel: ``(name, position_ms, loops_left)``, or None when none does.

        ``position_ms`` is in the clip's own time; ``loops_left`` counts the repeats of its loop
        region still to come (-1 = until stopped).

        Raises
        ------
        ParameterError
            A bad channel.
        ServerError
            The server refused (e.g. no such channel).
        NoReplyError
            No answer within the timeout.
        """
        base = f"{self._prefix}/ch/{_channel(channel, optional=False)}"

        def match(reply: Reply) -> bool:
            if reply.address != f"{base}/clip":
                return False
            args = reply.args
            ok = len(args) == 3 and isinstance(args[0], str) and all(isinstance(a, (int, float)) for a in args[1:])
            if not ok:
                self.stats.malformed += 1
            return ok

        name, position, left = self.request(f"{base}/get", "clip", types="s", match=match, timeout=timeout).args
        return None if not name else (str(name), float(position), int(left))

    def follow_setting(self, name: str, timeout: float | None = None) -> float | str:
        """Live Follow's ``gain`` (dB), ``gate`` (dB) or ``focus`` (a name), as the server holds it.

        Raises
        ------
        ParameterError
            An unknown name.
        ServerError
            The server refused (e.g. follow is not running: serve without ``--follow``).
        NoReplyError
            No answer within the timeout.
        """
        if name not in FOLLOW_SETTINGS:
            raise ParameterError(f"unknown follow setting {name!r}; known: {', '.join(FOLLOW_SETTINGS)}")
        want = f"{self._prefix}/follow/{name}"
        kind = str if name == "focus" else (int, float)

        def match(reply: Reply) -> bool:
            if reply.address != want:
                return False
            ok = len(reply.args) == 1 and isinstance(reply.args[0], kind) and not isinstance(reply.args[0], bool)
            if not ok:
                self.stats.malformed += 1
            return ok

        value = self.request(f"{self._prefix}/follow/get", name, types="s", match=match, timeout=timeout).args[0]
        return str(value) if name == "focus" else float(value)

    def status(self, timeout: float | None = None) -> dict[str, Any]:
        """The server's ``/status.reply`` as a dict (docs/osc.md lists the keys).

        E.g. ``{"version": "<vibsynth.__version__>", "channels": 2, "rate": 48000.0, ..., "ch1.intensity": 0.5, ...}``;
        -1 means the engine does not report that value.

        Raises
        ------
        NoReplyError
            No answer within the timeout.
        """

        def match(reply: Reply) -> bool:
            if reply.address != f"{self._prefix}/status.reply":
                return False
            ok = len(reply.args) % 2 == 0 and all(isinstance(k, str) for k in reply.args[::2])
            if not ok:
                self.stats.malformed += 1
            return ok

        reply = self.request(f"{self._prefix}/status", match=match, timeout=timeout)
        return dict(zip(reply.args[::2], reply.args[1::2]))

    def ping(self, timeout: float | None = None) -> float:
        """Round-trip time to the server in seconds (``/ping`` -> ``/pong``).

        Raises
        ------
        NoReplyError
            No answer within the timeout.
        """
        token = next(self._ids) & 0x7FFFFFFF
        pong = f"{self._prefix}/pong"
        started = time.perf_counter()
        self.request(
            f"{self._prefix}/ping",
            token,
            types="i",
            match=lambda r: r.address == pong and r.args == (token,),
            timeout=timeout,
        )
        return time.perf_counter() - started

    def sync(self, timeout: float | None = None) -> None:
        """Wait until the engine applied every command sent before; raise if the server refused any of them.

        Raises
        ------
        ServerError
            For the commands refused since the last :meth:`sync` (all of them in
            ``errors``; the first in ``address`` and ``message``).
        NoReplyError
            No answer within the timeout.
        """
        sync_id = next(self._ids) & 0x7FFFFFFF
        synced = f"{self._prefix}/synced"
        with self._lock:
            refused: tuple[tuple[str, str], ...] = ()
            try:
                self.request(
                    f"{self._prefix}/sync",
                    sync_id,
                    types="i",
                    match=lambda r: r.address == synced and r.args == (sync_id,),
                    timeout=timeout,
                )
            except ServerError as exc:  # the engine did not catch up in time (osc.sync_timeout)
                refused = exc.errors
            errors = tuple(self._pending) + refused
            self._pending.clear()
        if errors:
            raise ServerError(errors[0][0], errors[0][1], errors)

    def take_errors(self) -> list[tuple[str, str]]:
        """``(address, message)`` of the refusals received so far and not yet reported; clears them."""
        with self._lock:
            self._drain()
            errors = list(self._pending)
            self._pending.clear()
        return errors
