"""OSC address space: concrete addresses, OSC 1.0 pattern matching, routing to methods.

The address space is a fixed table built once from the prefix and the channel count,
e.g. ``/vibsynth/intensity`` (all channels) and ``/vibsynth/ch/2/intensity``
(channel 2, 1-based in addresses, 0-based in :class:`Route`). An incoming address
is looked up directly when it holds no pattern characters (the fast path for
every-frame VR traffic); otherwise it is translated to a regular expression
(OSC 1.0: ``?``, ``*``, ``[abc]``, ``[a-z]``, ``[!abc]``, ``{foo,bar}``) and matched
against the whole table. Pattern results are cached (bounded), so a client
sending ``/vibsynth/ch/*/intensity`` every frame pays for the regex once.
"""
from __future__ import annotations

import re
from collections import OrderedDict
from dataclasses import dataclass
from typing import Iterable

from vibsynth.errors import ConfigError, ParameterError

__all__ = [
    "PATTERN_CHARS",
    "Route",
    "AddressSpace",
    "pattern_to_regex",
    "normalize_prefix",
    "GLOBAL_METHODS",
    "CHANNEL_METHODS",
]

PATTERN_CHARS = frozenset("*?[]{}")

GLOBAL_METHODS = (
    "intensity", "balance", "texture", "glide", "mute", "panic", "preset", "speed",
    "get", "status", "ping", "sync", "notify", "learn",
)
"""Methods under ``{prefix}/``; they act on every channel (or on the server)."""

CHANNEL_METHODS = ("intensity", "balance", "texture", "glide", "mute", "preset", "speed", "get")
"""Methods under ``{prefix}/ch/{n}/``; they act on channel n only."""

_MAX_PATTERN_LEN = 256


@dataclass(frozen=True, slots=True)
class Route:
    """Where a concrete address leads: ``method`` name and 0-based ``channel`` (None = all)."""

    method: str
    channel: int | None


def normalize_prefix(prefix: str | None) -> str:
    """Validate the configured prefix; return it without a trailing slash (``""`` = no prefix).

    Raises
    ------
    ConfigError
        If it does not start with ``/`` or contains pattern characters or spaces.
    """
    if prefix is None or prefix in ("", "/"):
        return ""
    prefix = str(prefix).rstrip("/")
    if not prefix.startswith("/") or any(c in PATTERN_CHARS or c.isspace() or c in "#," for c in prefix):
        raise ConfigError(f"osc.prefix {prefix!r} must start with '/' and contain no spaces or OSC pattern characters")
    return prefix


def pattern_to_regex(pattern: str) -> re.Pattern[str]:
    """Translate an OSC 1.0 address pattern into a compiled, anchored regular expression.

    Raises
    ------
    ParameterError
        For an unbalanced ``[`` or ``{`` or an over-long pattern.
    """
    if len(pattern) > _MAX_PATTERN_LEN:
        raise ParameterError(f"address pattern longer than {_MAX_PATTERN_LEN} characters")
    out = []
    i, n = 0, len(pattern)
    while i < n:
        c = pattern[i]
        if c == "*":
            out.append("[^/]*")
        elif c == "?":
            out.append("[^/]")
        elif c == "[":
            end = pattern.find("]", i + 1)
            if end < 0:
                raise ParameterError("unbalanced '[' in address pattern")
            body = pattern[i + 1:end]
            negate = body.startswith("!")
            if negate:
                body = body[1:]
            if not body or "/" in body:
                raise ParameterError("empty or invalid '[...]' in address pattern")
            parts = []
            j = 0
            while j < len(body):
                if j + 2 < len(body) and body[j + 1] == "-":
                    lo, hi = body[j], body[j + 2]
                    if lo > hi:
                        lo, hi = hi, lo
                    parts.append(f"{re.escape(lo)}-{re.escape(hi)}")
                    j += 3
                else:
                    parts.append(re.escape(body[j]))
                    j += 1
            out.append(("[^/" if negate else "[") + "".join(parts) + "]")
            i = end
        elif c == "{":
            end = pattern.find("}", i + 1)
            if end < 0:
                raise ParameterError("unbalanced '{' in address pattern")
            words = pattern[i + 1:end].split(",")
            if any("/" in w for w in words):
                raise ParameterError("'/' inside '{...}' in address pattern")
            out.append("(?:" + "|".join(re.escape(w) for w in words) + ")")
            i = end
        elif c in "]}":
            raise ParameterError(f"unbalanced '{c}' in address pattern")
        else:
            out.append(re.escape(c))
        i += 1
    try:
        return re.compile("".join(out) + r"\Z")
    except re.error as exc:  # e.g. a reversed range that escaped the checks above
        raise ParameterError(f"invalid address pattern: {exc}") from None


class AddressSpace:
    """The table of concrete addresses and the matcher.

    Parameters
    ----------
    prefix : str
        Address prefix, e.g. ``/vibsynth`` (``""`` for none).
    channels : int
        Number of engine channels (addresses use 1..channels).
    cache_size : int
        Most distinct patterns remembered.
    """

    def __init__(self, prefix: str, channels: int, *, cache_size: int = 512) -> None:
        self.prefix = normalize_prefix(prefix)
        self.channels = int(channels)
        self._routes: dict[str, Route] = {}
        for method in GLOBAL_METHODS:
            self._routes[f"{self.prefix}/{method}"] = Route(method, None)
        for ch in range(self.channels):
            for method in CHANNEL_METHODS:
                self._routes[f"{self.prefix}/ch/{ch + 1}/{method}"] = Route(method, ch)
        self._cache: OrderedDict[str, tuple[Route, ...]] = OrderedDict()
        self._cache_size = cache_size

    @property
    def addresses(self) -> tuple[str, ...]:
        """Every concrete address, in table order."""
        return tuple(self._routes)

    def address_of(self, method: str, channel: int | None = None) -> str:
        """The concrete address of a method (``channel`` 0-based, None = global form)."""
        if channel is None:
            return f"{self.prefix}/{method}"
        return f"{self.prefix}/ch/{channel + 1}/{method}"

    def match(self, address: str) -> tuple[Route, ...]:
        """Routes an address (or pattern) leads to; empty when nothing matches.

        Raises
        ------
        ParameterError
            For an invalid pattern (unbalanced brackets, too long).
        """
        route = self._routes.get(address)
        if route is not None:
            return (route,)
        if not any(c in PATTERN_CHARS for c in address):
            return ()
        cached = self._cache.get(address)
        if cached is not None:
            self._cache.move_to_end(address)
            return cached
        regex = pattern_to_regex(address)
        found = tuple(r for a, r in self._routes.items() if regex.match(a))
        self._cache[address] = found
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return found

    @staticmethod
    def group(routes: Iterable[Route]) -> list[tuple[str, tuple[int, ...] | None]]:
        """Merge matched routes into one call per method: ``(method, channels)``.

        A global route wins over per-channel routes of the same method (channels=None);
        per-channel routes are merged into a sorted tuple, so
        ``/vibsynth/ch/*/intensity`` becomes one engine command for every channel.
        """
        merged: dict[str, set[int] | None] = {}
        for route in routes:
            if route.channel is None:
                merged[route.method] = None
            elif route.method not in merged:
                merged[route.method] = {route.channel}
            elif merged[route.method] is not None:
                merged[route.method].add(route.channel)  # type: ignore[union-attr]
        return [(m, None if chans is None else tuple(sorted(chans))) for m, chans in merged.items()]
