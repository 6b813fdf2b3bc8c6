"""OSC 1.0 address patterns: semantics, a fuzz test against a reference matcher, time bounds.

Issue 12, fault 1: a pattern of a few dozen ``*`` (under 100 bytes) made the regular
expression it was translated to backtrack exponentially and froze the server. The
matcher is now a dynamic programme (no backtracking); these tests compare it with an
independent brute-force matcher (recursive, memoised) on random patterns and bound the
time of every match relative to a plain match measured in the same test.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.control.osc.fakes import FakePeer, make_controller
from vibsynth.control.osc.address import (
    CHANNEL_METHODS,
    GLOBAL_METHODS,
    MAX_FANOUT,
    MAX_PATTERN_LEN,
    SOURCE_METHODS,
    AddressSpace,
    compile_pattern,
)
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.handler import OscHandler
from vibsynth.errors import ParameterError
from vibsynth.settings.models_sources import MAX_SOURCES

ROOT = Path(__file__).resolve().parents[3]

PLAIN = "/vibsynth/ch/*/intensity"


# ---------------------------------------------------------------------- reference matcher
def _reference_valid(pattern: str) -> bool:
    """OSC 1.0 syntax as the server accepts it: brackets closed within a part, ``[]`` not empty."""
    if len(pattern) > MAX_PATTERN_LEN:
        return False
    i = 0
    while i < len(pattern):
        c = pattern[i]
        if c in "]}":
            return False
        if c in "[{":
            close = "]" if c == "[" else "}"
            end = pattern.find(close, i + 1)
            if end < 0 or "/" in pattern[i + 1 : end]:
                return False
            body = pattern[i + 1 : end]
            if c == "[" and body in ("", "!"):
                return False
            i = end
        i += 1
    return True


def _reference_in_set(body: str, char: str) -> bool:
    negate = body.startswith("!")
    if negate:
        body = body[1:]
    hit = False
    j = 0
    while j < len(body):
        if j + 2 < len(body) and body[j + 1] == "-":
            low, high = min(body[j], body[j + 2]), max(body[j], body[j + 2])
            hit = hit or low <= char <= high
            j += 3
        else:
            hit = hit or char == body[j]
            j += 1
    return hit != negate


def reference_match(pattern: str, address: str) -> bool:
    """Brute force over the raw strings: try every way, memoised on (pattern index, address index)."""

    @functools.cache
    def at(p: int, a: int) -> bool:
        if p == len(pattern):
            return a == len(address)
        c = pattern[p]
        char_ok = a < len(address) and address[a] != "/"
        if c == "*":
            return at(p + 1, a) or (char_ok and at(p, a + 1))
        if c == "?":
            return char_ok and at(p + 1, a + 1)
        if c == "[":
            end = pattern.index("]", p + 1)
            return char_ok and _reference_in_set(pattern[p + 1 : end], address[a]) and at(end + 1, a + 1)
        if c == "{":
            end = pattern.index("}", p + 1)
            return any(address.startswith(w, a) and at(end + 1, a + len(w)) for w in pattern[p + 1 : end].split(","))
        return a < len(address) and address[a] == c and at(p + 1, a + 1)

    return at(0, 0)


# ---------------------------------------------------------------------- helpers
class MatchWork:
    """Counts the matcher's work, in steps a machine's speed does not change.

    Each ``_match_part(tokens, text)`` call runs a dynamic programme over the positions of
    ``text``; a step of it costs at most ``len(text) + 1`` positions times the token's length.
    ``worst`` is the largest ratio, over the calls, of the positions it visited to the
    linear bound ``(len(text) + 1) x (pattern part's length + 1)``: at most 1 for a matcher
    linear in both, far above for one that backtracks.
    """

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        from vibsynth.control.osc import address as module

        self.calls = 0
        self.worst = 0.0
        real_match, real_step = module._match_part, module._step
        visited = [0]

        def step(kind, arg, text, positions):
            out = real_step(kind, arg, text, positions)
            visited[0] += len(positions) + len(out)
            return out

        def match_part(tokens, text):
            visited[0] = 0
            result = real_match(tokens, text)
            length = sum(len(arg) if isinstance(arg, str) else 1 for _, arg in tokens)
            self.worst = max(self.worst, visited[0] / (2 * (len(text) + 1) * (length + 1)))
            self.calls += 1
            return result

        monkeypatch.setattr(module, "_step", step)
        monkeypatch.setattr(module, "_match_part", match_part)


def _outcome(space: AddressSpace, pattern: str) -> set[str] | str:
    try:
        routes = space.match(pattern)
    except ParameterError:
        return "error"
    return {space.address_of(r.method, r.channel) for r in routes}


_WILD = "*?[]{},!-/"
_ALPHABET = _WILD + "abceghilnstvy0123456789"


def _mutate(address: str, rng) -> str:
    """A pattern derived from a real address (so that many patterns match something)."""
    out = []
    i = 0
    while i < len(address):
        c = address[i]
        roll = rng.random() * 2.0  # about one position in eight is changed
        if roll < 0.08:
            out.append("*")
            i += int(rng.integers(0, 4))
            continue
        if roll < 0.14 and c != "/":
            out.append("?")
        elif roll < 0.18 and c != "/":
            other = str(rng.choice(list("abin0129")))
            out.append("[" + ("!" if rng.random() < 0.3 else "") + "".join(sorted({c, other})) + "]")
        elif roll < 0.21 and c != "/":
            out.append("[" + other_range(c, rng) + "]")
        elif roll < 0.25 and c != "/":
            j = min(len(address), i + int(rng.integers(1, 5)))
            word = address[i:j].split("/")[0]
            alts = [word, word[::-1], ""][: int(rng.integers(1, 4))]
            out.append("{" + ",".join(alts) + "}")
            i += len(word)
            continue
        elif roll < 0.28:
            out.append(str(rng.choice(list(_ALPHABET))))
        else:
            out.append(c)
        i += 1
    return "".join(out)


def other_range(c: str, rng) -> str:
    low = chr(ord(c) - int(rng.integers(0, 3)))
    high = chr(ord(c) + int(rng.integers(-1, 3)))
    return f"{low}-{high}"


def _random_pattern(rng) -> str:
    n = int(rng.integers(1, 40))
    return "/" + "".join(str(c) for c in rng.choice(list(_ALPHABET), size=n))


# ---------------------------------------------------------------------- semantics
@pytest.mark.parametrize(
    "pattern, address, expected",
    [
        ("/a/?", "/a/b", True),
        ("/a?b", "/a/b", False),  # ? never matches /
        ("/a*", "/a/b", False),  # * never crosses /
        ("/*/b", "/a/b", True),
        ("/a/*", "/a/", True),  # * matches an empty run
        ("/x[abc]", "/xb", True),
        ("/x[!abc]", "/xb", False),
        ("/x[!abc]", "/xd", True),
        ("/x[a-c]", "/xb", True),
        ("/x[c-a]", "/xb", True),  # a reversed range is read low to high
        ("/x[-a]", "/x-", True),  # - first is literal
        ("/x[a-]", "/x-", True),  # - last is literal
        ("/{foo,bar}/z", "/bar/z", True),
        ("/{foo,bar}/z", "/baz/z", False),
        ("/a{,b}", "/a", True),  # an empty alternative
        ("/x*y*z", "/xaaayaaz", True),
        ("/x*y*z", "/xaaayaa", False),
        ("/a,b", "/a,b", True),  # , outside {} is literal
    ],
)
def test_pattern_semantics(pattern, address, expected):
    assert compile_pattern(pattern).matches(address) is expected
    assert reference_match(pattern, address) is expected


@pytest.mark.parametrize(
    "bad, fragment",
    [
        ("/vibsynth/ch/[1/x", "unbalanced '['"),
        ("/vibsynth/{a/b}", "unbalanced '{'"),
        ("/vibsynth/]", "unbalanced ']'"),
        ("/vibsynth/x}", "unbalanced '}'"),
        ("/vibsynth/[]", "empty '[...]'"),
        ("/vibsynth/[!]", "empty '[...]'"),
        ("/x/" + "*" * 300, f"longer than {MAX_PATTERN_LEN}"),
    ],
)
def test_pattern_errors_name_the_problem(bad, fragment):
    with pytest.raises(ParameterError, match=fragment.replace("[", r"\[").replace("{", r"\{")):
        compile_pattern(bad)


def test_sixty_four_channels_fit_the_fanout_cap():
    space = AddressSpace("/vibsynth", 64)
    sources = len(SOURCE_METHODS) * MAX_SOURCES
    assert len(space.addresses) == len(GLOBAL_METHODS) + len(CHANNEL_METHODS) * 64 + sources <= MAX_FANOUT
    routes = space.match("/vibsynth/ch/*/intensity")
    assert [r.channel for r in routes] == list(range(64)) and {r.method for r in routes} == {"intensity"}
    assert len(space.match("/vibsynth/*/*/*")) == len(CHANNEL_METHODS) * 64 + sources


def test_fanout_beyond_the_cap_is_an_error_and_nothing_is_done():
    ctl = make_controller(channels=4)
    handler = OscHandler(ctl, sync_worker=None)
    handler.space = AddressSpace("/vibsynth", 4, max_fanout=8)
    peer = FakePeer()
    handler.handle_packet(encode_message("/vibsynth/ch/*/intensity", (0.5,)), peer)  # 4 routes: fine
    assert [c.value for c in ctl.engine.commands] == [0.5]
    handler.handle_packet(encode_message("/vibsynth/ch/*/*", (0.25,)), peer)  # 4 x every channel method
    address, message = peer.errors()[-1]
    assert address == "/vibsynth/ch/*/*"
    assert f"matches {4 * len(CHANNEL_METHODS)} addresses, more than the limit of 8" in message
    assert [c.value for c in ctl.engine.commands] == [0.5]
    assert ctl.error_counts["osc.bad_pattern"] == 1


def test_pattern_cache_is_bounded_and_remembers_errors():
    space = AddressSpace("/vibsynth", 4, cache_size=4)
    for k in range(10):
        space.match(f"/vibsynth/ch/{k}*/intensity")
    assert len(space._cache) == 4
    for _ in range(2):
        with pytest.raises(ParameterError, match="unbalanced"):
            space.match("/vibsynth/[x")
    assert space._cache["/vibsynth/[x"] == "unbalanced '[' in address pattern"


# ---------------------------------------------------------------------- fuzz + time budget
def test_fuzz_against_reference_in_linear_work(rng, monkeypatch):
    """4000 random patterns against a 12-channel table (182 addresses): the same matches and the
    same errors as the brute-force reference, each in work linear in pattern and address (counted
    in the matcher's steps, not timed: a timing depends on the machine's load)."""
    space = AddressSpace("/vibsynth", 12, cache_size=0)
    addresses = space.addresses
    work = MatchWork(monkeypatch)
    compared, matched = 0, 0
    for k in range(4000):
        pattern = _mutate(str(rng.choice(addresses)), rng) if k % 4 else _random_pattern(rng)
        got = _outcome(space, pattern)
        if _reference_valid(pattern):
            want: set[str] | str = {a for a in addresses if reference_match(pattern, a)}
        else:
            want = "error"
        assert got == want, pattern
        compared += 1
        matched += bool(want) and want != "error"
    print(f"\nfuzz: {compared} patterns, {matched} matching something; {work.calls} part matches, worst work "
          f"{work.worst:.2f} of the linear bound")  # fmt: skip
    assert matched > 1000 and work.calls > 1000
    assert work.worst <= 1.0


_PATHOLOGICAL_CHILD = r"""
import json, sys
from vibsynth.control.osc.address import AddressSpace
space = AddressSpace("/vibsynth", 64, cache_size=0)
print(json.dumps({p: len(space.match(p)) for p in json.loads(sys.argv[1])}))
"""

PATHOLOGICAL = {
    "/vibsynth/" + "*a" * 40 + "x": 0,
    "/vibsynth/" + "*" * 28 + "x": 0,  # the regex took ~5 s on this one
    "/vibsynth/" + "*" * 200: len([m for m in GLOBAL_METHODS if "/" not in m]),  # not follow/gain...
    "/vibsynth/" + "*" * 245 + "x": 0,
    "/vibsynth/ch/" + "*?" * 118 + "/*": 0,
    "/vibsynth/ch/*/" + "{a,b,i,n,t,e,s,y,}*" * 12: len(CHANNEL_METHODS) * 64,
}


def test_pathological_patterns_match_in_linear_work(monkeypatch):
    """Patterns that froze the regex matcher: the right matches in work linear in pattern and
    address (counted); and, in a child process with a 60 s bound, a regression fails this test
    instead of hanging the suite."""
    assert all(len(p) <= MAX_PATTERN_LEN for p in PATHOLOGICAL)
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PATHOLOGICAL_CHILD, json.dumps(list(PATHOLOGICAL))],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("a pathological address pattern took more than 60 s (exponential backtracking?)")
    assert json.loads(proc.stdout) == PATHOLOGICAL
    space = AddressSpace("/vibsynth", 64, cache_size=0)
    work = MatchWork(monkeypatch)
    for pattern, count in PATHOLOGICAL.items():
        assert len(space.match(pattern)) == count, pattern
    print(f"\npathological patterns: {work.calls} part matches, worst work {work.worst:.2f} of the linear bound")
    assert work.calls > 0 and work.worst <= 1.0


@pytest.mark.parametrize(
    "channels, address, reason",
    [
        (1, "/vibsynth/ch/2/intensity", "channel 2 out of range (this server has 1 channel: 1..1)"),
        (8, "/vibsynth/ch/9/texture", "channel 9 out of range (this server has 8 channels: 1..8)"),
        (
            1,
            "/vibsynth/ch/99999999999999999999/get",
            "channel 999999999999 out of range (this server has 1 channel: 1..1)",
        ),
        (1, "/vibsynth/balanse", "unknown address (did you mean .../balance?)"),
        (1, "/vibsynth/ch/1/nothing", "unknown address"),
        (1, "/other/ch/2/intensity", "unknown address"),
        (1, "/vibsynth/ch/2/" + "x" * 5000, "unknown address"),
    ],
)
def test_why_an_address_is_unknown(channels, address, reason):
    space = AddressSpace("/vibsynth", channels)
    assert space.match(address) == ()
    assert space.why_unknown(address) == reason


def test_why_unknown_never_compares_long_names(monkeypatch):
    """difflib's cost grows with the text an attacker sends: only short ASCII names are compared."""
    import difflib

    compared = []
    real = difflib.get_close_matches
    monkeypatch.setattr(
        difflib, "get_close_matches", lambda word, *a, **k: compared.append(word) or real(word, *a, **k)
    )
    space = AddressSpace("/vibsynth", 2)
    for address in ("/vibsynth/" + "x" * 60_000, "/vibsynth/ch/1/" + "é" * 10, "/vibsynth/ch/1/intensty"):
        space.why_unknown(address)
    assert compared == ["intensty"]
