"""OSC 1.0 wire format: decode datagrams into messages and bundles, encode replies.

A strict, bounded decoder written for a server that must survive anything the
network sends: every length is checked against the datagram, bundle nesting is
limited, unknown type tags and non-UTF-8 strings are rejected, and the only
exception that escapes :func:`decode_packet` is :class:`MalformedPacket`.
(python-osc's parser can loop on a negative bundle element size, recurse without
bound on nested bundles and leak ``UnicodeDecodeError``; this one cannot.)

Timetags are kept as raw 64-bit NTP values; :data:`IMMEDIATE` (1) means "now".
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from vibsynth.errors import ParameterError

__all__ = [
    "MalformedPacket",
    "Message",
    "Bundle",
    "Packet",
    "IMMEDIATE",
    "MAX_BUNDLE_DEPTH",
    "decode_packet",
    "encode_message",
    "encode_bundle",
    "infer_types",
    "ntp_to_unix",
    "unix_to_ntp",
    "iter_messages",
]

IMMEDIATE = 1
"""The OSC timetag meaning "immediately" (0x0000000000000001)."""

MAX_BUNDLE_DEPTH = 8
"""Bundles nested deeper than this are rejected as malformed."""

NTP_UNIX_OFFSET = 2208988800
"""Seconds from the NTP epoch (1900-01-01) to the Unix epoch (1970-01-01)."""

_BUNDLE_TAG = b"#bundle\x00"
_I32 = struct.Struct(">i")
_I64 = struct.Struct(">q")
_U64 = struct.Struct(">Q")
_F32 = struct.Struct(">f")
_F64 = struct.Struct(">d")


class MalformedPacket(ParameterError):
    """A datagram is not valid OSC 1.0 (truncated, bad padding, unknown type tag...)."""


@dataclass(frozen=True, slots=True)
class Message:
    """One decoded OSC message.

    Attributes
    ----------
    address : str
        Address or address pattern (starts with ``/``).
    args : tuple
        Decoded arguments: int (``i``, ``h``), float (``f``, ``d``), str (``s``, ``S``, ``c``),
        bytes (``b``), bool (``T``, ``F``), None (``N``), ``math.inf`` (``I``),
        int timetag (``t``), bytes (``r``, ``m``), tuple (``[...]`` arrays).
    types : str
        Type tags without the leading comma.
    """

    address: str
    args: tuple
    types: str = ""


@dataclass(frozen=True, slots=True)
class Bundle:
    """One decoded OSC bundle: raw NTP ``timetag`` and its elements (messages or bundles)."""

    timetag: int
    elements: tuple


Packet = Message | Bundle


def ntp_to_unix(timetag: int) -> float:
    """Convert a 64-bit NTP timetag to seconds since the Unix epoch (``time.time()`` scale)."""
    return (timetag >> 32) - NTP_UNIX_OFFSET + (timetag & 0xFFFFFFFF) / 4294967296.0


def unix_to_ntp(seconds: float) -> int:
    """Convert ``time.time()``-scale seconds to a 64-bit NTP timetag."""
    ntp = seconds + NTP_UNIX_OFFSET
    whole = int(ntp)
    frac = int((ntp - whole) * 4294967296.0)
    return ((whole & 0xFFFFFFFF) << 32) | (frac & 0xFFFFFFFF)


# ---------------------------------------------------------------------- decoding
def _string(data: bytes, index: int, what: str) -> tuple[str, int]:
    end = data.find(b"\x00", index)
    if end < 0:
        raise MalformedPacket(f"unterminated {what}")
    padded = (end + 4) & ~3
    if padded > len(data):
        raise MalformedPacket(f"{what} padding runs past the end")
    try:
        text = data[index:end].decode("utf-8")
    except UnicodeDecodeError:
        raise MalformedPacket(f"{what} is not UTF-8") from None
    return text, padded


def _fixed(data: bytes, index: int, size: int, tag: str) -> int:
    if index + size > len(data):
        raise MalformedPacket(f"argument '{tag}' truncated")
    return index + size


def _decode_message(data: bytes) -> Message:
    address, index = _string(data, 0, "address")
    if index >= len(data):
        return Message(address, (), "")
    tags, index = _string(data, index, "type tag string")
    if not tags.startswith(","):
        raise MalformedPacket("type tag string does not start with ','")
    tags = tags[1:]
    args: list = []
    stack: list[list] = [args]
    for tag in tags:
        if tag == "i":
            end = _fixed(data, index, 4, tag)
            value: object = _I32.unpack_from(data, index)[0]
        elif tag == "f":
            end = _fixed(data, index, 4, tag)
            value = _F32.unpack_from(data, index)[0]
        elif tag in "sS":
            value, end = _string(data, index, "string argument")
        elif tag == "d":
            end = _fixed(data, index, 8, tag)
            value = _F64.unpack_from(data, index)[0]
        elif tag == "h":
            end = _fixed(data, index, 8, tag)
            value = _I64.unpack_from(data, index)[0]
        elif tag == "t":
            end = _fixed(data, index, 8, tag)
            value = _U64.unpack_from(data, index)[0]
        elif tag == "b":
            start = _fixed(data, index, 4, tag)
            size = _I32.unpack_from(data, index)[0]
            if size < 0:
                raise MalformedPacket("negative blob size")
            end = start + ((size + 3) & ~3)
            if end > len(data):
                raise MalformedPacket("blob truncated")
            value = bytes(data[start : start + size])
        elif tag == "c":
            end = _fixed(data, index, 4, tag)
            code = _I32.unpack_from(data, index)[0]
            if not 0 <= code <= 0x10FFFF:
                raise MalformedPacket("invalid char argument")
            value = chr(code)
        elif tag in "rm":
            end = _fixed(data, index, 4, tag)
            value = bytes(data[index:end])
        elif tag == "T":
            value, end = True, index
        elif tag == "F":
            value, end = False, index
        elif tag == "N":
            value, end = None, index
        elif tag == "I":
            value, end = math.inf, index
        elif tag == "[":
            if len(stack) > MAX_BUNDLE_DEPTH:
                raise MalformedPacket("arrays nested too deeply")
            inner: list = []
            stack[-1].append(inner)
            stack.append(inner)
            continue
        elif tag == "]":
            if len(stack) < 2:
                raise MalformedPacket("unbalanced ']' in type tags")
            done = stack.pop()
            stack[-1][-1] = tuple(done)
            continue
        else:
            raise MalformedPacket(f"unknown type tag {tag!r}")
        stack[-1].append(value)
        index = end
    if len(stack) != 1:
        raise MalformedPacket("unbalanced '[' in type tags")
    if index != len(data):
        raise MalformedPacket("trailing bytes after the last argument")
    return Message(address, tuple(args), tags)


def _decode(data: bytes, depth: int) -> Packet:
    if data[:1] == b"/":
        return _decode_message(data)
    if data[:8] == _BUNDLE_TAG:
        if depth >= MAX_BUNDLE_DEPTH:
            raise MalformedPacket(f"bundles nested deeper than {MAX_BUNDLE_DEPTH}")
        if len(data) < 16:
            raise MalformedPacket("bundle header truncated")
        timetag = _U64.unpack_from(data, 8)[0]
        elements = []
        index = 16
        size_total = len(data)
        while index < size_total:
            if index + 4 > size_total:
                raise MalformedPacket("bundle element size truncated")
            size = _I32.unpack_from(data, index)[0]
            index += 4
            if size <= 0 or size & 3 or index + size > size_total:
                raise MalformedPacket(f"bad bundle element size {size}")
            elements.append(_decode(data[index : index + size], depth + 1))
            index += size
        return Bundle(timetag, tuple(elements))
    raise MalformedPacket("neither a message ('/') nor a bundle ('#bundle')")


def decode_packet(data: bytes) -> Packet:
    """Decode one OSC packet (a datagram or one SLIP frame).

    Parameters
    ----------
    data : bytes
        The packet.

    Returns
    -------
    Message or Bundle

    Raises
    ------
    MalformedPacket
        For anything that is not valid OSC 1.0 (never any other exception).
    """
    if not data or len(data) & 3:
        raise MalformedPacket(f"packet size {len(data)} is not a positive multiple of 4")
    try:
        return _decode(bytes(data), 0)
    except MalformedPacket:
        raise
    except (struct.error, ValueError, IndexError, OverflowError, RecursionError) as exc:  # defensive
        raise MalformedPacket(f"undecodable packet: {exc}") from None


def iter_messages(packet: Packet, timetag: int = IMMEDIATE) -> Iterator[tuple[Message, int]]:
    """Flatten a packet into ``(message, timetag)`` pairs, depth first.

    A nested bundle's own timetag wins unless it is :data:`IMMEDIATE`, in which case it
    inherits the enclosing bundle's (OSC 1.0 requires inner timetags >= outer ones).
    """
    if isinstance(packet, Message):
        yield packet, timetag
        return
    own = packet.timetag if packet.timetag != IMMEDIATE else timetag
    for element in packet.elements:
        yield from iter_messages(element, own)


# ---------------------------------------------------------------------- encoding
def _pad_string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return raw + b"\x00" * (4 - len(raw) % 4)


def infer_types(args: Sequence[object]) -> str:
    """OSC type tags for Python values.

    int -> i (h beyond 32 bits), float -> f, str -> s, bytes -> b, bool -> T/F, None -> N.
    """
    tags = []
    for arg in args:
        if isinstance(arg, bool):
            tags.append("T" if arg else "F")
        elif isinstance(arg, int):
            tags.append("i" if -(2**31) <= arg < 2**31 else "h")
        elif isinstance(arg, float):
            tags.append("f")
        elif isinstance(arg, str):
            tags.append("s")
        elif isinstance(arg, (bytes, bytearray)):
            tags.append("b")
        elif arg is None:
            tags.append("N")
        else:
            raise ParameterError(f"cannot encode {arg!r} as an OSC argument")
    return "".join(tags)


def encode_message(address: str, args: Sequence[object] = (), types: str | None = None) -> bytes:
    """Encode an OSC message.

    Parameters
    ----------
    address : str
        OSC address (starts with ``/``).
    args : sequence
        Argument values.
    types : str, optional
        Type tags (without comma) forcing the encoding, e.g. ``"fi"``; inferred when None.
        Tags without data (``T F N I``) take a (ignored) value from ``args`` when ``args`` has
        one value per tag (as :func:`decode_packet` returns them), else none.

    Returns
    -------
    bytes
    """
    if types is None:
        types = infer_types(args)
    parts = [_pad_string(address), _pad_string("," + types)]
    values = iter(args)
    flags_take_values = len(args) == len(types)
    try:
        for tag in types:
            if tag in "TFNI":
                if flags_take_values:
                    next(values)
                continue
            value = next(values)
            if tag == "i":
                parts.append(_I32.pack(int(value)))  # type: ignore[call-overload]
            elif tag == "f":
                parts.append(_F32.pack(float(value)))  # type: ignore[arg-type]
            elif tag == "d":
                parts.append(_F64.pack(float(value)))  # type: ignore[arg-type]
            elif tag == "h":
                parts.append(_I64.pack(int(value)))  # type: ignore[call-overload]
            elif tag == "t":
                parts.append(_U64.pack(int(value)))  # type: ignore[call-overload]
            elif tag in "sS":
                parts.append(_pad_string(str(value)))
            elif tag == "c":
                parts.append(_I32.pack(ord(str(value))))
            elif tag == "b":
                blob = bytes(value)  # type: ignore[call-overload]
                parts.append(_I32.pack(len(blob)) + blob + b"\x00" * (-len(blob) % 4))
            else:
                raise ParameterError(f"cannot encode OSC type tag {tag!r}")
    except StopIteration:
        raise ParameterError(f"type tags {types!r} need more arguments than given") from None
    except (struct.error, TypeError, ValueError) as exc:
        raise ParameterError(f"cannot encode arguments {list(args)!r} as {types!r}: {exc}") from None
    return b"".join(parts)


def encode_bundle(timetag: int, elements: Sequence[bytes]) -> bytes:
    """Encode a bundle from already encoded elements (messages or bundles)."""
    parts = [_BUNDLE_TAG, _U64.pack(timetag)]
    for element in elements:
        parts.append(_I32.pack(len(element)))
        parts.append(element)
    return b"".join(parts)
