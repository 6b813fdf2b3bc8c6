"""Replies to OSC senders: loopback test, reply budget against amplification, path redaction."""

from __future__ import annotations

import functools
import ipaddress
import re
from collections.abc import Callable

from vibsynth.control.osc.address import GLOBAL_METHODS
from vibsynth.control.osc.workers import PeerLike

_LOOPBACK = {"127.0.0.1", "::1", "localhost"}

REPLY_AMPLIFICATION = 3
"""UDP replies to a client on another host total at most this many times the bytes of the
packet that caused them (the anti-amplification limit of QUIC, RFC 9000 section 8.1): a
forged source address cannot turn the server into an amplifier. Error replies are cut to
fit; other replies that do not fit are not sent (counted) and an error says why. Clients on
this host and TCP clients (whose address the handshake proved) are not limited."""


@functools.lru_cache(maxsize=1024)
def is_loopback(host: str) -> bool:
    """Is ``host`` (an IP address string, IPv4-mapped IPv6 included) a loopback address?"""
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return ip.is_loopback


# An absolute path: /a/b, ~/a, C:\a or C:/a, not preceded by a word character or a path
# character (so "mm/s" and "a/b" are left alone). One character class repeated: linear time.
_PATH = re.compile(r"(?<![\w.~/\\-])(?:~|[A-Za-z]:)?[/\\][^\s'\"`,;:()\[\]{}<>]+")
_OWN_PARTS = frozenset(GLOBAL_METHODS) | {"ch", "source"}


def _is_osc_address(token: str, prefix: str) -> bool:
    if prefix:
        return token == prefix or token.startswith(prefix + "/")
    parts = token.split("/")
    return "\\" not in token and len(parts) > 1 and parts[1] in _OWN_PARTS


def redact_paths(text: str, prefix: str = "/vibsynth") -> str:
    """Replace every absolute file-system path in ``text`` by its base name (``<path>`` if none).

    Error messages sent to the network must not disclose where files live (user names,
    folders); ``/home/ana/.config/vibsynth/presets/x.yaml:3: ...`` becomes ``x.yaml:3: ...``.
    OSC addresses under ``prefix`` (e.g. ``/vibsynth/ch/1/intensity``) are kept.
    """

    def replace(match: re.Match[str]) -> str:
        token = match.group(0)
        if _is_osc_address(token, prefix):
            return token
        name = token.rstrip("/\\").replace("\\", "/").rsplit("/", 1)[-1]
        return name if name and name != "~" and not name.endswith(":") else "<path>"

    return _PATH.sub(replace, text)


def _osc_string_size(text: str) -> int:
    """Bytes ``text`` takes in an OSC message (UTF-8, NUL-terminated, padded to 4)."""
    return (len(text.encode("utf-8")) // 4 + 1) * 4


def fit_osc_string(text: str, size: int) -> str:
    """``text``, cut (ending in ``...``) so that it takes at most ``size`` bytes in an OSC message.

    ``size`` >= 4 (the empty string's size).
    """
    limit = (size // 4) * 4 - 1  # longest UTF-8 text that fits
    raw = text.encode("utf-8")
    if len(raw) <= limit:
        return text
    if limit < 3:
        return raw[: max(limit, 0)].decode("utf-8", "ignore")
    return raw[: limit - 3].decode("utf-8", "ignore") + "..."


class ReplyBudget:
    """A UDP peer on another host, seen while one request is handled: its replies share a byte budget.

    Parameters
    ----------
    peer : PeerLike
        The real peer.
    limit : int
        Bytes all replies to this request may take (:data:`REPLY_AMPLIFICATION` x its size).
    on_refused : callable
        ``on_refused(budget, size)`` when a reply of ``size`` bytes does not fit (not sent).
    """

    __slots__ = ("peer", "limit", "room", "request", "refused", "_on_refused")

    def __init__(self, peer: PeerLike, limit: int, on_refused: Callable[[ReplyBudget, int], None]) -> None:
        self.peer = peer
        self.limit = limit
        self.room = limit
        self.request = ""
        self.refused = False
        self._on_refused = on_refused

    @property
    def key(self) -> tuple:
        return self.peer.key

    @property
    def address(self) -> tuple[str, int] | None:
        return getattr(self.peer, "address", None)

    def send(self, data: bytes) -> bool:
        """Send when it fits in what is left of the budget; otherwise report it and send nothing."""
        if len(data) > self.room:
            self._on_refused(self, len(data))
            return False
        self.room -= len(data)
        return self.peer.send(data)
