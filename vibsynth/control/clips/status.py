"""What clips play, as status pairs (OSC ``/status.reply``, the studio's status panel) and per channel."""

from __future__ import annotations

from typing import Any

from vibsynth.control.clips import player_of

__all__ = ["clip_values", "clip_status"]


def clip_values(controller: Any, channel: int) -> tuple[str, float, int]:
    """``(name, position_ms, loops_left)`` of what plays on a channel (0-based); ``("", 0, 0)`` when idle.

    ``position_ms`` is in the clip's own time; ``loops_left`` counts the repeats of its loop
    region still to come (-1 = until stopped). A clip timetagged to start later shows at 0.
    """
    player = player_of(controller)
    playing = None if player is None else player.playing(channel)
    if playing is None:
        return "", 0.0, 0
    return playing.name, float(playing.position.clip_ms), int(playing.position.loops_left)


def clip_status(controller: Any) -> list[tuple[str, object]]:
    """``clips_playing``, then ``ch{n}.clip`` (name, "" = none), ``ch{n}.clip_ms``, ``ch{n}.clip_loops_left``,
    then ``source{k}.clip`` (name) for each touch source a clip plays on.

    Empty when no clip player runs.
    """
    player = player_of(controller)
    if player is None:
        return []
    rows = [clip_values(controller, c) for c in range(controller.channels)]
    pairs: list[tuple[str, object]] = [("clips_playing", sum(1 for name, _, _ in rows if name))]
    for c, (name, position, left) in enumerate(rows):
        pairs += [(f"ch{c + 1}.clip", name), (f"ch{c + 1}.clip_ms", position), (f"ch{c + 1}.clip_loops_left", left)]
    pairs += [(f"source{k + 1}.clip", name) for k, name in sorted(player.sources.names().items())]
    return pairs
