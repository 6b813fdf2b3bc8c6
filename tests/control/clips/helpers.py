"""Clips for the player and compiler tests, built with the real clip model."""

from __future__ import annotations

from collections.abc import Sequence

from vibsynth.settings.clips import Clip, Keyframe, Transient


def make_clip(
    keyframes: Sequence[tuple],
    *,
    duration_ms: float,
    transients: Sequence[tuple] = (),
    loop: tuple[float, float] | None = None,
    name: str = "test",
) -> Clip:
    """A clip from ``(t_ms, intensity, balance[, interp])`` and ``(t_ms, intensity, balance, decay_ms)`` tuples."""
    keys = [
        Keyframe(t_ms=float(k[0]), intensity=float(k[1]), balance=float(k[2]), interp=k[3] if len(k) > 3 else "linear")
        for k in keyframes
    ]
    trs = [
        Transient(t_ms=float(t[0]), intensity=float(t[1]), balance=float(t[2]), decay_ms=float(t[3]))
        for t in transients
    ]
    return Clip(
        name=name,
        duration_ms=float(duration_ms),
        keyframes=tuple(keys),
        transients=tuple(trs),
        loop=loop,
        tags=(),
        description="",
        path=None,
    )
