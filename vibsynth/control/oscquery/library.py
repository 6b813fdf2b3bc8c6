"""The preset and clip libraries as OSCQuery nodes: one read-only node per preset and per clip.

``{prefix}/presets/NAME`` holds the preset's knobs (TYPE ``ff``: intensity, balance) and
``{prefix}/clips/NAME`` the clip's length (TYPE ``f``, ``time.ms``); their DESCRIPTION says
what the file says and which message uses it (``/vibsynth/preset s NAME``,
``/vibsynth/play s NAME``). They are ACCESS 1: a tool shows the library as a list it can read
(and a button per entry that sends the setter), and a file added to or removed from the
library folders on disk is a node added or removed: WebSocket clients get ``PATH_ADDED`` /
``PATH_REMOVED`` (a file edited on disk changes the VALUE, or the DESCRIPTION: ``PATH_CHANGED``).
A file edited into one that no longer loads keeps its last good version (the library's rule),
so its node stays as it was.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from vibsynth.control.oscquery.tree import Context, NodeSpec
from vibsynth.errors import VibsynthError

__all__ = ["LibraryNodes"]


def _reader(library: Any, name: str, read: Callable[[Any], list[Any]]) -> Callable[[Context], Sequence[Any] | None]:
    def value(ctx: Context) -> Sequence[Any] | None:
        try:
            return read(library.get(name))
        except VibsynthError:  # removed or broken since the last refresh: no VALUE until it loads
            return None

    return value


def _described(library: Any, name: str, what: str, usage: str) -> str:
    try:
        text = str(library.get(name).description or "").strip()
    except VibsynthError as exc:
        text = f"does not load: {exc}"
    return f"{what} {name}" + (f": {text}" if text else "") + f" ({usage})"


class LibraryNodes:
    """A :class:`~vibsynth.control.oscquery.tree.NodeTable` of the preset and clip libraries.

    Parameters
    ----------
    prefix : str
        The OSC address prefix (``/vibsynth``).
    presets, clips : library or None
        :class:`~vibsynth.settings.library.PresetLibrary` /
        :class:`~vibsynth.settings.clips.ClipLibrary` (``names()``, ``get(name)``); None = none.
    intensity_range, balance_range : dict
        The preset nodes' RANGE items (the knobs' live bounds).
    """

    def __init__(
        self,
        prefix: str,
        presets: Any,
        clips: Any,
        *,
        intensity_range: dict[str, Any],
        balance_range: dict[str, Any],
    ) -> None:
        self.prefix = prefix
        self.presets = presets
        self.clips = clips
        self._preset_range: list[dict[str, Any] | None] = [intensity_range, balance_range]

    def nodes(self) -> Mapping[str, NodeSpec]:
        """``{prefix}/presets/NAME`` and ``{prefix}/clips/NAME`` for every name the libraries hold now."""
        out: dict[str, NodeSpec] = {}
        if self.presets is not None:
            for name in self.presets.names():
                out[f"{self.prefix}/presets/{name}"] = NodeSpec(
                    "ff",
                    _described(self.presets, name, "preset", f"load: {self.prefix}/preset s {name}"),
                    _reader(self.presets, name, lambda p: [float(p.intensity), float(p.balance)]),
                    lambda ctx: self._preset_range,
                    writable=False,
                )
        if self.clips is not None:
            for name in self.clips.names():
                out[f"{self.prefix}/clips/{name}"] = NodeSpec(
                    "f",
                    _described(self.clips, name, "clip", f"play: {self.prefix}/play s {name}"),
                    _reader(self.clips, name, lambda c: [float(c.duration_ms)]),
                    lambda ctx: [{"MIN": 0.0}],
                    unit=("time.ms",),
                    writable=False,
                )
        return out
