"""The parts of a status report every control surface shows the same way (OSC ``/status``, the studio).

Each function returns ``(key, value)`` pairs with the keys of OSC ``/status.reply``
(docs/osc.md); -1 means the engine does not report a value. The OSC handler assembles its
reply from them with its own counters; the studio shows that reply when OSC runs, and these
parts when it does not.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from vibsynth._version import __version__
from vibsynth.control.follow import follower_of

__all__ = ["engine_status", "output_status", "channel_status", "engine_stat", "follow_status"]

Pairs = list[tuple[str, object]]


def engine_stat(engine: Any, names: Sequence[str], default: float) -> float:
    """First available engine statistic among ``names`` (attributes or a ``stats`` mapping/method)."""
    stats = getattr(engine, "stats", None)
    try:
        if callable(stats):
            stats = stats()
    except Exception:  # noqa: BLE001 - the engine is optional here, never let status fail
        stats = None
    for name in names:
        value = None
        if isinstance(stats, dict):
            value = stats.get(name)
        elif stats is not None:
            value = getattr(stats, name, None)
        if value is None:
            value = getattr(engine, name, None)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return value
    return default


def engine_status(controller: Any, block_size: int | None = None) -> Pairs:
    """Version, channels, rate, block, underflows, load, schedule, uptime, stream frame."""
    engine = controller.engine
    return [
        ("version", __version__),
        ("channels", int(controller.channels)),
        ("rate", float(getattr(engine, "fs", -1.0))),
        ("block_size", int(engine_stat(engine, ("block_size", "blocksize", "block_frames"), block_size or -1))),
        ("underflows", int(engine_stat(engine, ("underflows", "xruns", "underruns"), -1))),
        ("load", float(engine_stat(engine, ("render_load", "load_avg", "load", "cpu_load"), -1.0))),
        ("load_peak", float(engine_stat(engine, ("load_peak",), -1.0))),
        ("late_commands", int(engine_stat(engine, ("late_commands",), -1))),
        ("scheduled_pending", int(engine_stat(engine, ("pending",), -1))),
        ("schedule_full", int(engine_stat(engine, ("schedule_full",), -1))),
        ("uptime", float(time.monotonic() - controller.started_at)),
        ("frame", int(engine_stat(engine, ("frame_position",), -1))),
    ]


def output_status(controller: Any, tap: Any, fit: Callable[[str, int], str]) -> Pairs:
    """The audio output (state, reason, device) and the last control error, texts cut by ``fit(text, 400)``.

    The service sets ``controller.output``: ``streaming``, ``null``, or ``device lost`` with
    the reason while it is retried.
    """
    pairs: Pairs = []
    output = getattr(controller, "output", None)
    if output is not None:
        describe = getattr(output, "describe", None)
        pairs += [
            ("output", str(getattr(output, "state", ""))),
            ("output_reason", str(getattr(output, "state_reason", ""))),
            ("device", fit(str(describe()) if callable(describe) else "", 400)),
        ]
    errors = tap.last_errors()
    if errors:
        pairs += [
            ("last_error", fit(errors[-1].text, 400)),
            ("last_error_age", float(max(0.0, time.time() - errors[-1].time))),
        ]
    return pairs


def channel_status(controller: Any) -> Pairs:
    """``ch{n}.intensity``, ``.balance``, ``.glide`` (ms), ``.mute``, ``.preset`` of every channel."""
    pairs: Pairs = []
    for ch, s in enumerate(controller.state()):
        pairs += [
            (f"ch{ch + 1}.intensity", float(s.intensity)),
            (f"ch{ch + 1}.balance", float(s.balance)),
            (f"ch{ch + 1}.glide", float(s.glide_s * 1000.0)),
            (f"ch{ch + 1}.mute", int(s.muted)),
            (f"ch{ch + 1}.preset", s.preset or ""),
        ]
    return pairs


def follow_status(controller: Any, fit: Callable[[str, int], str] = lambda text, size: text[:size]) -> Pairs:
    """``follow.device`` (the input and its state), ``follow.level_db`` (tracked input level, the
    gate's units), ``follow.gate`` (1 = open), ``follow.gain``/``follow.gate_db`` (dB),
    ``follow.focus``, ``follow.stale_frames``, ``follow.losses``/``follow.recoveries`` (inputs lost and
    back) and ``ch{n}.follow`` (1 = follows); none when follow is off."""
    follower = follower_of(controller)
    if follower is None:
        return []
    pairs: Pairs = [
        ("follow.device", fit(follower.device_text(), 400)),
        ("follow.level_db", float(round(follower.level_db(), 2))),
        ("follow.gate", int(follower.gate_open())),
        ("follow.gain", float(follower.gain_db)),
        ("follow.gate_db", float(follower.gate_db)),
        ("follow.focus", str(follower.focus)),
        ("follow.stale_frames", int(follower.stale_frames)),
        ("follow.losses", int(follower.losses)),
        ("follow.recoveries", int(follower.recoveries)),
    ]
    return pairs + [(f"ch{c + 1}.follow", int(follower.is_on(c))) for c in follower.channels()]
