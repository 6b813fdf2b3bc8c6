"""OSC address space: concrete addresses, OSC 1.0 pattern matching, routing to methods.

The address space is a fixed table built once from the prefix and the channel count,
e.g. ``/vibsynth/intensity`` (all channels) and ``/vibsynth/ch/2/intensity``
(channel 2, 1-based in addresses, 0-based in :class:`Route`). An incoming address
is looked up directly when it holds no pattern characters (the fast path for
every-frame VR traffic); otherwise it is compiled by :func:`compile_pattern`
(OSC 1.0: ``?``, ``*``, ``[abc]``, ``[a-z]``, ``[!abc]``, ``{foo,bar}``) and matched
against the whole table. Pattern results are cached (bounded), so a client
sending ``/vibsynth/ch/*/intensity`` every frame pays for the match once.

Matching never backtracks. A pattern is split at ``/`` into parts (``*`` and ``?``
never cross ``/``), and each part is matched against one address part by a
dynamic programme over the set of reachable positions in the address part, one
pattern token at a time: time O(len(pattern part) x len(address part)), memory
O(len(address part)). A pattern of at most :data:`MAX_PATTERN_LEN` characters
therefore costs at most a few milliseconds against the whole table, whatever
its shape (a translated regular expression backtracked exponentially on
``/vibsynth/******...x``). A pattern may lead to at most :data:`MAX_FANOUT` routes.
"""

from __future__ import annotations

import difflib
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass

from vibsynth.errors import ConfigError, ParameterError
from vibsynth.limits import OSC_PREFIX_MAX
from vibsynth.settings.models_sources import MAX_SOURCES

__all__ = [
    "PATTERN_CHARS",
    "MAX_PATTERN_LEN",
    "MAX_FANOUT",
    "Route",
    "AddressPattern",
    "AddressSpace",
    "compile_pattern",
    "normalize_prefix",
    "GLOBAL_METHODS",
    "CHANNEL_METHODS",
    "SOURCE_METHODS",
]

PATTERN_CHARS = frozenset("*?[]{}")

MAX_PATTERN_LEN = 256
"""Longest address pattern accepted (characters); longer patterns get an error reply."""

MAX_FANOUT = 1024
"""Most routes one pattern may lead to; a pattern matching more is an error (nothing is done).

The table holds ``21 + 11 x channels + 16 x 12`` routes (the sources'), 917 at the maximum of 64
channels (``audio.channels``), so every pattern, ``/vibsynth/ch/*/intensity`` and even
``/vibsynth/*/*/*`` included, fits on every supported configuration; the cap bounds the
work of one message should the table ever grow.
"""

GLOBAL_METHODS = (
    "intensity",
    "balance",
    "texture",
    "glide",
    "mute",
    "panic",
    "preset",
    "speed",
    "get",
    "status",
    "ping",
    "sync",
    "notify",
    "learn",
    "monitor",
    "play",
    "stop",
    "follow/gain",
    "follow/gate",
    "follow/range",
    "follow/focus",
    "follow/get",
)
"""Methods under ``{prefix}/``; they act on every channel (or on the server). ``follow/...`` are
live Follow's (``{prefix}/follow/gain``...: control/osc/follow.py)."""

CHANNEL_METHODS = (
    "intensity",
    "balance",
    "texture",
    "glide",
    "mute",
    "preset",
    "speed",
    "get",
    "play",
    "stop",
    "follow",
)
"""Methods under ``{prefix}/ch/{n}/``; they act on channel n only."""

SOURCE_METHODS = (
    "pos",
    "texture",
    "intensity",
    "balance",
    "preset",
    "radius",
    "rolloff",
    "on",
    "speed",
    "get",
    "play",
    "stop",
)
"""Methods under ``{prefix}/source/{k}/`` (k = 1..16): the touch sources (docs/vr.md). Their routes
are named ``source/<method>`` and carry the 0-based source index in ``Route.channel``."""

# Token kinds of a compiled pattern part.
_LITERAL, _ANY, _STAR, _SET, _CHOICE = range(5)

Token = tuple[int, object]
"""``(kind, argument)``: literal text, ``?``, ``*``, a character set ``(negate, ranges)``, or words."""


@dataclass(frozen=True, slots=True)
class Route:
    """Where a concrete address leads: ``method`` name and 0-based ``channel`` (None = all).

    For a source method (``source/pos``...) ``channel`` is the 0-based source index."""

    method: str
    channel: int | None


def normalize_prefix(prefix: str | None) -> str:
    """Validate the configured prefix; return it without a trailing slash (``""`` = no prefix).

    Raises
    ------
    ConfigError
        If it does not start with ``/``, contains pattern characters or spaces, or is longer than
        :data:`~vibsynth.limits.OSC_PREFIX_MAX` (its fast-path addresses would not fit the table).
    """
    if prefix is None or prefix in ("", "/"):
        return ""
    prefix = str(prefix).rstrip("/")
    if not prefix.startswith("/") or any(c in PATTERN_CHARS or c.isspace() or c in "#," for c in prefix):
        raise ConfigError(f"osc.prefix {prefix!r} must start with '/' and contain no spaces or OSC pattern characters")
    if len(prefix) > OSC_PREFIX_MAX:
        raise ConfigError(f"osc.prefix is {len(prefix)} characters long (allowed: at most {OSC_PREFIX_MAX})")
    return prefix


# ---------------------------------------------------------------------- compiling
def _char_set(body: str) -> tuple[bool, tuple[tuple[str, str], ...]]:
    """Parse the inside of ``[...]``: ``(negate, ((low, high), ...))``.

    ``a-z`` is a range (a reversed one is read low to high); a ``-`` first or last is literal.

    Raises
    ------
    ParameterError
        For an empty set.
    """
    negate = body.startswith("!")
    if negate:
        body = body[1:]
    if not body:
        raise ParameterError("empty '[...]' in address pattern")
    ranges = []
    j = 0
    while j < len(body):
        if j + 2 < len(body) and body[j + 1] == "-":
            low, high = sorted((body[j], body[j + 2]))
            ranges.append((low, high))
            j += 3
        else:
            ranges.append((body[j], body[j]))
            j += 1
    return negate, tuple(ranges)


def _closing(part: str, start: int, close: str) -> int:
    """Index of ``close`` after ``part[start]`` (an opening bracket); ParameterError when missing."""
    end = part.find(close, start + 1)
    if end < 0:
        raise ParameterError(f"unbalanced '{part[start]}' in address pattern")
    return end


def _compile_part(part: str) -> tuple[Token, ...]:
    """Tokens of one pattern part (no ``/`` inside); adjacent literals merged, ``**`` = ``*``.

    Raises
    ------
    ParameterError
        For an unbalanced ``[``, ``]``, ``{`` or ``}``, or an empty ``[]``.
    """
    tokens: list[Token] = []
    literal: list[str] = []

    def push(kind: int, arg: object = None) -> None:
        if literal:
            tokens.append((_LITERAL, "".join(literal)))
            literal.clear()
        if kind == _STAR and tokens and tokens[-1][0] == _STAR:
            return
        tokens.append((kind, arg))

    i = 0
    while i < len(part):
        c = part[i]
        if c == "*":
            push(_STAR)
        elif c == "?":
            push(_ANY)
        elif c == "[":
            end = _closing(part, i, "]")
            push(_SET, _char_set(part[i + 1 : end]))
            i = end
        elif c == "{":
            end = _closing(part, i, "}")
            push(_CHOICE, tuple(sorted(set(part[i + 1 : end].split(",")))))
            i = end
        elif c in "]}":
            raise ParameterError(f"unbalanced '{c}' in address pattern")
        else:
            literal.append(c)
        i += 1
    if literal:
        tokens.append((_LITERAL, "".join(literal)))
    return tuple(tokens)


def _in_set(char: str, spec: tuple[bool, tuple[tuple[str, str], ...]]) -> bool:
    negate, ranges = spec
    return any(low <= char <= high for low, high in ranges) != negate


def _step(kind: int, arg: object, text: str, positions: set[int]) -> set[int]:
    """Positions in ``text`` reachable after one more token, from ``positions`` (all <= len(text))."""
    n = len(text)
    if kind == _STAR:
        return set(range(min(positions), n + 1))
    if kind == _LITERAL:
        assert isinstance(arg, str)
        return {i + len(arg) for i in positions if text.startswith(arg, i)}
    if kind == _ANY:
        return {i + 1 for i in positions if i < n}
    if kind == _SET:
        return {i + 1 for i in positions if i < n and _in_set(text[i], arg)}  # type: ignore[arg-type]
    assert isinstance(arg, tuple)
    return {i + len(word) for i in positions for word in arg if text.startswith(word, i)}


def _match_part(tokens: tuple[Token, ...], text: str) -> bool:
    """Does one compiled pattern part match the whole address part ``text``?

    A dynamic programme over positions: after each token, the set of positions in
    ``text`` where a match of the tokens so far can end. Each token costs
    O(len(text) x its length), so the whole part O(len(text) x len(pattern part)).
    """
    positions = {0}
    for kind, arg in tokens:
        positions = _step(kind, arg, text, positions)
        if not positions:
            return False
    return len(text) in positions


class AddressPattern:
    """A compiled OSC 1.0 address pattern; :meth:`matches` tests one concrete address.

    Parameters
    ----------
    pattern : str
        E.g. ``/vibsynth/ch/[1-3]/{intensity,balance}``.

    Raises
    ------
    ParameterError
        For an over-long pattern (more than :data:`MAX_PATTERN_LEN` characters) or an
        unbalanced ``[``/``{``/``]``/``}`` or empty ``[]``.
    """

    __slots__ = ("pattern", "parts")

    def __init__(self, pattern: str) -> None:
        if len(pattern) > MAX_PATTERN_LEN:
            raise ParameterError(f"address pattern longer than {MAX_PATTERN_LEN} characters")
        self.pattern = pattern
        self.parts = tuple(_compile_part(part) for part in pattern.split("/"))

    def literal(self, index: int) -> str | None:
        """The text of part ``index`` when it holds no wildcard (None otherwise)."""
        tokens = self.parts[index]
        if not tokens:
            return ""
        if len(tokens) == 1 and tokens[0][0] == _LITERAL:
            return tokens[0][1]  # type: ignore[return-value]
        return None

    def matches_part(self, index: int, text: str) -> bool:
        """Does part ``index`` (0 = before the first ``/``) match the address part ``text``?"""
        return _match_part(self.parts[index], text)

    def matches(self, address: str) -> bool:
        """Does the pattern match the whole concrete ``address``?"""
        texts = address.split("/")
        return len(texts) == len(self.parts) and all(
            _match_part(tokens, text) for tokens, text in zip(self.parts, texts)
        )


def compile_pattern(pattern: str) -> AddressPattern:
    """Compile an OSC 1.0 address pattern (see :class:`AddressPattern`)."""
    return AddressPattern(pattern)


# ---------------------------------------------------------------------- the table
class AddressSpace:
    """The table of concrete addresses and the matcher.

    Parameters
    ----------
    prefix : str
        Address prefix, e.g. ``/vibsynth`` (``""`` for none).
    channels : int
        Number of engine channels (addresses use 1..channels).
    cache_size : int
        Most distinct patterns remembered (results and errors).
    max_fanout : int
        Most routes one pattern may lead to (:data:`MAX_FANOUT`).
    """

    def __init__(self, prefix: str, channels: int, *, cache_size: int = 512, max_fanout: int = MAX_FANOUT) -> None:
        self.prefix = normalize_prefix(prefix)
        self.channels = int(channels)
        self.max_fanout = int(max_fanout)
        self._routes: dict[str, Route] = {}
        for method in GLOBAL_METHODS:
            self._routes[f"{self.prefix}/{method}"] = Route(method, None)
        for ch in range(self.channels):
            for method in CHANNEL_METHODS:
                self._routes[f"{self.prefix}/ch/{ch + 1}/{method}"] = Route(method, ch)
        for k in range(MAX_SOURCES):
            for method in SOURCE_METHODS:
                self._routes[f"{self.prefix}/source/{k + 1}/{method}"] = Route(f"source/{method}", k)
        self._tree: dict = {}  # address parts -> nested dicts; the Route under the key None
        for address, route in self._routes.items():
            node = self._tree
            for text in address.split("/"):
                node = node.setdefault(text, {})
            node[None] = route
        self._cache: OrderedDict[str, tuple[Route, ...] | str] = OrderedDict()
        self._cache_size = cache_size

    @property
    def addresses(self) -> tuple[str, ...]:
        """Every concrete address, in table order."""
        return tuple(self._routes)

    def why_unknown(self, address: str) -> str:
        """Why an address (that matched nothing) is unknown, in words for the error reply.

        ``/vibsynth/ch/2/intensity`` on a one-channel server is "channel 2 out of range (this
        server has 1 channel)"; a method name that is close to a real one gets "did you mean";
        anything else is "unknown address".
        """
        parts = address[len(self.prefix) :].split("/") if address.startswith(self.prefix + "/") else []
        plural = "channel" if self.channels == 1 else "channels"
        if len(parts) == 4 and parts[1] == "ch" and parts[3] in CHANNEL_METHODS and parts[2].isdigit():
            n = int(parts[2][:12])
            if not 1 <= n <= self.channels:
                return f"channel {n} out of range (this server has {self.channels} {plural}: 1..{self.channels})"
        if len(parts) == 4 and parts[1] == "source" and parts[3] in SOURCE_METHODS and parts[2].isdigit():
            k = int(parts[2][:12])
            if not 1 <= k <= MAX_SOURCES:
                return f"source {k} out of range (sources are 1..{MAX_SOURCES})"
        method = parts[-1] if parts else ""
        candidates: tuple[str, ...] = CHANNEL_METHODS if len(parts) == 4 and parts[1] == "ch" else GLOBAL_METHODS
        if len(parts) == 4 and parts[1] == "source":
            candidates = SOURCE_METHODS
        # a near miss of a real method name only: difflib's cost grows with the text, and an
        # attacker chooses the text, so long or non-ASCII names are not compared at all
        short = len(method) <= 16 and method.isascii()
        close = difflib.get_close_matches(method, candidates, n=1, cutoff=0.75) if short else []
        if close:
            return f"unknown address (did you mean .../{close[0]}?)"
        return "unknown address"

    def address_of(self, method: str, channel: int | None = None) -> str:
        """The concrete address of a method (``channel`` 0-based, None = global form; a source method's
        ``channel`` is its source index)."""
        if channel is None:
            return f"{self.prefix}/{method}"
        if method.startswith("source/"):
            return f"{self.prefix}/source/{channel + 1}/{method[7:]}"
        return f"{self.prefix}/ch/{channel + 1}/{method}"

    def match(self, address: str) -> tuple[Route, ...]:
        """Routes an address (or pattern) leads to; empty when nothing matches.

        Raises
        ------
        ParameterError
            For an invalid pattern (unbalanced brackets, too long) or one leading to
            more than ``max_fanout`` routes (then nothing at all is done).
        """
        route = self._routes.get(address)
        if route is not None:
            return (route,)
        if not any(c in PATTERN_CHARS for c in address):
            return ()
        cached = self._cache.get(address)
        if cached is None:
            try:
                cached = self._search(address)
            except ParameterError as exc:
                cached = str(exc)
            self._cache[address] = cached
            if len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(address)
        if isinstance(cached, str):
            raise ParameterError(cached)
        return cached

    def _search(self, address: str) -> tuple[Route, ...]:
        """Match a pattern against the whole table (uncached).

        The table is a tree of address parts; a pattern part that is plain text is a
        dictionary lookup, any other is matched against each child part once per node
        (a few dozen distinct parts in all: the prefix, ``ch``, channel numbers, methods).
        """
        pattern = AddressPattern(address)
        found: list[Route] = []
        self._walk(pattern, self._tree, 0, {}, found)
        if len(found) > self.max_fanout:
            raise ParameterError(
                f"address pattern matches {len(found)} addresses, more than the limit of "
                f"{self.max_fanout}; nothing was done"
            )
        return tuple(found)

    def _walk(
        self, pattern: AddressPattern, node: dict, index: int, seen: dict[tuple[int, str], bool], found: list[Route]
    ) -> None:
        """Collect (in table order) the routes below ``node`` matching pattern parts ``index..``."""
        if index == len(pattern.parts):
            route = node.get(None)
            if route is not None:
                found.append(route)
            return
        literal = pattern.literal(index)
        if literal is not None:
            child = node.get(literal)
            if child is not None:
                self._walk(pattern, child, index + 1, seen, found)
            return
        for text, child in node.items():
            if text is None:
                continue
            ok = seen.get((index, text))
            if ok is None:
                ok = seen[(index, text)] = pattern.matches_part(index, text)
            if ok:
                self._walk(pattern, child, index + 1, seen, found)

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
