"""VRChat's current avatar parameter values, read from its OSCQuery tree once it is found.

VRChat sends a parameter only when it changes. An avatar that already rests a hand on a
Contact Receiver when vibsynth starts would be felt only from the next change; VRChat's own
OSCQuery server, though, holds every parameter's current value under ``/avatar/parameters``
(``TYPE`` ``f``, ``i`` or ``T``; ``VALUE`` a one-entry array) and the avatar's id at
``/avatar/change``. :func:`read_avatar` reads that node once, bounded in size, depth, node
count and time, and returns what it holds as numbers (a bool 1/0), like the OSC messages.

Parameter names may hold ``/`` (``Go/Hand``, ``VF12_Touch/Left``): the tree nests them, and the
walk joins the parts back.
"""

from __future__ import annotations

import json
import math
import urllib.error
import urllib.request
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from vibsynth.errors import VibsynthError

__all__ = ["AVATAR_CAP", "MAX_DEPTH", "MAX_NODES", "AvatarValues", "parse_avatar", "read_avatar"]

#: Largest ``/avatar`` answer read (a large avatar's tree is about 100 kB).
AVATAR_CAP = 4 * 1024 * 1024
#: Deepest nesting of parameter names walked.
MAX_DEPTH = 16
#: Most nodes walked.
MAX_NODES = 20_000
_NUMBER_TYPES = frozenset("ifdh")


@dataclass(frozen=True)
class AvatarValues:
    """What VRChat's tree said: the avatar's id ("" when absent) and each parameter's value."""

    avatar: str = ""
    parameters: Mapping[str, float] = field(default_factory=dict)
    skipped: int = 0  # nodes with no single finite number or bool as VALUE


def _value(node: Mapping[str, Any]) -> float | None:
    types, values = node.get("TYPE"), node.get("VALUE")
    if not isinstance(types, str) or len(types) != 1 or not isinstance(values, list) or len(values) != 1:
        return None
    value = values[0]
    if types in ("T", "F"):
        return float(value) if isinstance(value, bool) else None
    if types in _NUMBER_TYPES and isinstance(value, int | float) and not isinstance(value, bool):
        number = float(value)
        return number if math.isfinite(number) else None
    return None


def parse_avatar(tree: Any) -> AvatarValues:
    """The values in VRChat's ``/avatar`` node (a decoded OSCQuery JSON object).

    Raises
    ------
    VibsynthError
        Not an OSCQuery node, nested deeper than :data:`MAX_DEPTH` or more than
        :data:`MAX_NODES` nodes.
    """
    if not isinstance(tree, dict):
        raise VibsynthError("VRChat's /avatar is not an OSCQuery node")
    contents = tree.get("CONTENTS")
    contents = contents if isinstance(contents, dict) else {}
    change = contents.get("change")
    avatar = ""
    if isinstance(change, dict) and isinstance(change.get("VALUE"), list) and change["VALUE"]:
        first = change["VALUE"][0]
        avatar = first[:128] if isinstance(first, str) else ""
    parameters: dict[str, float] = {}
    skipped = 0
    stack: list[tuple[str, Any, int]] = []
    root = contents.get("parameters")
    if isinstance(root, dict) and isinstance(root.get("CONTENTS"), dict):
        stack = [(name, node, 1) for name, node in root["CONTENTS"].items()]
    walked = 0
    while stack:
        name, node, depth = stack.pop()
        walked += 1
        if walked > MAX_NODES:
            raise VibsynthError(f"VRChat's /avatar/parameters has more than {MAX_NODES} nodes")
        if depth > MAX_DEPTH:
            raise VibsynthError(f"VRChat's /avatar/parameters is nested deeper than {MAX_DEPTH}")
        if not isinstance(node, dict):
            skipped += 1
            continue
        children = node.get("CONTENTS")
        if isinstance(children, dict):
            stack.extend((f"{name}/{child}", sub, depth + 1) for child, sub in children.items())
        if "VALUE" in node or "TYPE" in node:
            value = _value(node)
            if value is None:
                skipped += 1
            else:
                parameters[name] = value
    return AvatarValues(avatar, parameters, skipped)


def read_avatar(oscquery_url: str, timeout_s: float = 2.0) -> AvatarValues:
    """``GET {oscquery_url}/avatar`` from VRChat's OSCQuery server, parsed by :func:`parse_avatar`.

    Raises
    ------
    VibsynthError
        No answer in time, an answer larger than :data:`AVATAR_CAP`, not JSON, or a tree
        :func:`parse_avatar` refuses (one line naming the URL).
    """
    url = oscquery_url.rstrip("/") + "/avatar"
    try:
        with urllib.request.urlopen(url, timeout=timeout_s) as response:  # noqa: S310 - VRChat's own server
            body = response.read(AVATAR_CAP + 1)
    except (OSError, urllib.error.URLError) as exc:
        raise VibsynthError(f"{url}: no answer ({exc})") from None
    if len(body) > AVATAR_CAP:
        raise VibsynthError(f"{url}: the answer is larger than {AVATAR_CAP // 1024} KiB")
    try:
        tree = json.loads(body)
    except (ValueError, RecursionError) as exc:  # json's own nesting limit raises RecursionError
        raise VibsynthError(f"{url}: not JSON ({type(exc).__name__}: {exc})") from None
    try:
        return parse_avatar(tree)
    except VibsynthError as exc:
        raise VibsynthError(f"{url}: {exc}") from None
