"""Meta Haptics Studio ``.haptic`` files (the Lofelt haptic data model, version 1): read into a
:class:`HapticDesign`, and written from one.

What is read::

    {"version": {"major": 1, "minor": 0, "patch": 0},
     "metadata": {"editor": ..., "author": ..., "source": ..., "project": ..., "tags": [...], "description": ...},
     "signals": {"continuous": {"envelopes": {
         "amplitude": [{"time": 0.0, "amplitude": 0.2},
                       {"time": 0.2, "amplitude": 0.5, "emphasis": {"amplitude": 0.9, "frequency": 0.7}}, ...],
         "frequency": [{"time": 0.0, "frequency": 0.4}, ...]}}}}

Times are seconds; amplitude, frequency and the emphasis values are 0..1 (a value outside is an
error, as in Meta's own validation). Both envelopes are linear between breakpoints, whose times
must not decrease (two breakpoints at the same time are a step). Before the first amplitude
breakpoint the signal is silent; the frequency envelope holds its first and last values outside
its breakpoints (0.5 where there is none). An emphasis is a tap at its breakpoint's time. The clip
ends at the last breakpoint of either envelope.

Writing (:func:`meta_haptic_data`) is the inverse, so that :func:`parse_meta_haptic` reads back the
design it was given: each segment's start and end become amplitude and frequency breakpoints
(a step is two breakpoints at the same time; a breakpoint a straight line through its neighbours
already passes is left out), and each tap becomes the emphasis of an amplitude breakpoint at its
time (one is added on the envelope where none is). An emphasis amplitude below the envelope's at
its time is raised to it: Meta plays an emphasis *on top of* the envelope, and a vibsynth
transient never dips below the curve either (``max(curve, transient)``), so nothing heard
changes. Of two taps at the same time (after rounding to the microsecond) the stronger is kept.
"""

from __future__ import annotations

import json
import os
from bisect import bisect_left, bisect_right
from pathlib import Path
from typing import Any

from vibsynth.errors import ClipError
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap
from vibsynth.formats.jsonio import JsonFields, JsonPath, load_json, parse_json

__all__ = [
    "MAX_HAPTIC_BYTES",
    "MAX_BREAKPOINTS",
    "MAX_TIME_S",
    "read_meta_haptic",
    "parse_meta_haptic",
    "meta_haptic_data",
    "meta_haptic_text",
]

#: ``.haptic`` files over this size are refused before they are read (a 35 s clip is ~200 KB).
MAX_HAPTIC_BYTES = 4 << 20
#: Most breakpoints in both envelopes together.
MAX_BREAKPOINTS = 100_000
#: Latest breakpoint time: a clip holds at most 10 minutes.
MAX_TIME_S = 600.0
WHAT = "a .haptic file"

_KEYS: dict[tuple[str, ...], set[str]] = {
    (): {"version", "metadata", "signals"},
    ("version",): {"major", "minor", "patch"},
    ("metadata",): {"editor", "author", "source", "project", "tags", "description"},
    ("signals",): {"continuous"},
    ("signals", "continuous"): {"envelopes"},
    ("signals", "continuous", "envelopes"): {"amplitude", "frequency"},
    ("signals", "continuous", "envelopes", "amplitude"): {"time", "amplitude", "emphasis"},
    ("signals", "continuous", "envelopes", "amplitude", "emphasis"): {"amplitude", "frequency"},
    ("signals", "continuous", "envelopes", "frequency"): {"time", "frequency"},
}


def _envelope(r: JsonFields, raw: Any, path: JsonPath, key: str, taps: list[Tap]) -> list[tuple[float, float]]:
    raw = r.items(raw, path)
    if len(raw) > MAX_BREAKPOINTS:
        raise r.fail(path, f"has {len(raw):,} breakpoints (allowed: at most {MAX_BREAKPOINTS:,})")
    points: list[tuple[float, float]] = []
    for i, item in enumerate(raw):
        ipath = path + (i,)
        bp = r.mapping(item, ipath)
        t = r.number(r.require(bp, "time", ipath), ipath + ("time",), 0.0, MAX_TIME_S)
        if points and t < points[-1][0]:
            raise r.fail(ipath + ("time",), f"= {t!r}: breakpoint times must not decrease (previous {points[-1][0]!r})")
        points.append((t, r.number(r.require(bp, key, ipath), ipath + (key,), 0.0, 1.0)))
        if "emphasis" in bp:
            epath = ipath + ("emphasis",)
            emphasis = r.mapping(bp["emphasis"], epath)
            taps.append(
                Tap(
                    t,
                    r.number(r.require(emphasis, "amplitude", epath), epath + ("amplitude",), 0.0, 1.0),
                    r.number(r.require(emphasis, "frequency", epath), epath + ("frequency",), 0.0, 1.0),
                )
            )
    return points


def _at(points: list[tuple[float, float]], times: list[float], t: float, *, left: bool, before: float | None) -> float:
    """An envelope at ``t`` (``left``: the limit from the left at a step); ``before`` = value before the first point.

    ``times`` are the points' times (given once: a lookup is a bisection).
    """
    k = (bisect_left(times, t) if left else bisect_right(times, t)) - 1
    if k < 0:
        return points[0][1] if before is None else before
    if k == len(points) - 1:
        return points[-1][1]
    (t0, v0), (t1, v1) = points[k], points[k + 1]
    return v0 if t1 == t0 else v0 + (t - t0) / (t1 - t0) * (v1 - v0)


def _from_data(data: Any, origin: str) -> HapticDesign:
    r = JsonFields(origin, _KEYS, ClipError)
    root = r.mapping(data, ())
    version = r.mapping(r.require(root, "version", ()), ("version",))
    major = r.require(version, "major", ("version",))
    if major != 1 or isinstance(major, bool):
        raise r.fail(("version", "major"), f"= {major!r}: this vibsynth reads .haptic version 1")
    path: JsonPath = ("signals", "continuous", "envelopes")
    signals = r.mapping(r.require(root, "signals", ()), path[:1])
    continuous = r.mapping(r.require(signals, "continuous", path[:1]), path[:2])
    envelopes = r.mapping(r.require(continuous, "envelopes", path[:2]), path)
    taps: list[Tap] = []
    amplitude = _envelope(r, r.require(envelopes, "amplitude", path), path + ("amplitude",), "amplitude", taps)
    if not amplitude:
        raise r.fail(path + ("amplitude",), "is empty (the amplitude envelope needs at least one breakpoint)")
    frequency = _envelope(r, envelopes.get("frequency", []), path + ("frequency",), "frequency", [])
    if not frequency:
        frequency = [(0.0, 0.5)]
    if len(amplitude) + len(frequency) > MAX_BREAKPOINTS:
        raise r.fail(path, f"more than {MAX_BREAKPOINTS:,} breakpoints; not a clip vibsynth reads")
    duration = max(amplitude[-1][0], frequency[-1][0] if "frequency" in envelopes else 0.0)
    edges = sorted({0.0, duration, *(t for t, _ in amplitude), *(t for t, _ in frequency if t < duration)})
    at, ft = [t for t, _ in amplitude], [t for t, _ in frequency]
    segments = [
        Segment(
            a,
            b,
            _at(amplitude, at, a, left=False, before=0.0),
            _at(amplitude, at, b, left=True, before=0.0),
            _at(frequency, ft, a, left=False, before=None),
            _at(frequency, ft, b, left=True, before=None),
        )
        for a, b in zip(edges, edges[1:])
    ]
    if duration <= 0:  # a single breakpoint at 0: its emphasis only
        segments = []
    meta = root.get("metadata")
    description: str = ""
    tags: tuple[str, ...] = ()
    if isinstance(meta, dict):
        r.mapping(meta, ("metadata",))
        if isinstance(meta.get("description"), str):
            description = meta["description"]
        if isinstance(meta.get("tags"), list):
            tags = tuple(t for t in meta["tags"] if isinstance(t, str))
    ignored = tuple(f"unknown field {u}" for u in r.unknown)
    return HapticDesign(tuple(segments), tuple(sorted(taps, key=lambda t: t.t)), duration, description, tags, ignored)


def parse_meta_haptic(text: str, origin: str = "<haptic>") -> HapticDesign:
    """Parse ``.haptic`` text (JSON) into a design.

    Raises
    ------
    ClipError
        Not JSON (truncated, NaN, too deep or large), not a version-1 ``.haptic`` file, a missing
        or out-of-range value, breakpoint times out of order: one line naming the file and the
        JSON path (``x.haptic: signals.continuous.envelopes.amplitude[2].time = ...``).
    """
    return _from_data(parse_json(text, origin, error=ClipError), origin)


def read_meta_haptic(path: str | os.PathLike[str]) -> HapticDesign:
    """Read a ``.haptic`` file (at most :data:`MAX_HAPTIC_BYTES`, refused before reading).

    See :func:`parse_meta_haptic`.
    """
    p = Path(path)
    return _from_data(load_json(p, error=ClipError, what=WHAT, max_bytes=MAX_HAPTIC_BYTES), str(p))


# --------------------------------------------------------------------------- writing
def _r(x: float) -> float:
    """Times and values as written: 6 decimals (a microsecond), no ``-0.0``."""
    return round(float(x), 6) + 0.0


def _breakpoints(segments: tuple[Segment, ...], start: str, end: str) -> list[tuple[float, float]]:
    """(time, value) breakpoints of one envelope (the segments' ``start``/``end`` values): a step is two."""
    points: list[tuple[float, float]] = []
    for seg in segments:
        a, b = (_r(seg.t0), _r(getattr(seg, start))), (_r(seg.t1), _r(getattr(seg, end)))
        if not points or points[-1] != a:
            points.append(a)
        points.append(b)
    return _pruned(points)


def _pruned(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Leave out breakpoints on the straight line through their neighbours (never one side of a step)."""
    out: list[tuple[float, float]] = []
    for t, v in points:
        if len(out) >= 2:
            (ta, va), (tb, vb) = out[-2], out[-1]
            if ta < tb < t and abs(va + (v - va) * (tb - ta) / (t - ta) - vb) <= 1e-9:
                out[-1] = (t, v)
                continue
        out.append((t, v))
    return out


def _value(points: list[tuple[float, float]], t: float) -> float:
    """The envelope at ``t`` (right-continuous at a step; held outside)."""
    times = [p[0] for p in points]
    return _at(points, times, t, left=False, before=points[0][1])


def _with_emphasis(amplitude: list[tuple[float, float]], taps: tuple[Tap, ...]) -> list[dict[str, Any]]:
    """Amplitude breakpoints as written, each tap the emphasis of the (last) breakpoint at its time."""
    strongest: dict[float, Tap] = {}
    for tap in taps:
        t = _r(tap.t)
        if t not in strongest or tap.intensity > strongest[t].intensity:
            strongest[t] = tap
    have = {t for t, _ in amplitude}
    points = amplitude + [(t, _r(_value(amplitude, t))) for t in sorted(strongest) if t not in have]
    points.sort(key=lambda p: p[0])  # stable: the two sides of a step keep their order
    out: list[dict[str, Any]] = [{"time": t, "amplitude": v} for t, v in points]
    for k, item in enumerate(out):
        hit = strongest.get(item["time"])
        if hit is not None and (k + 1 == len(out) or out[k + 1]["time"] != item["time"]):
            item["emphasis"] = {"amplitude": _r(max(hit.intensity, item["amplitude"])), "frequency": _r(hit.sharpness)}
    return out


def meta_haptic_data(design: HapticDesign, *, description: str = "", source: str = "") -> dict[str, Any]:
    """A ``.haptic`` document (plain data) that :func:`parse_meta_haptic` reads back as ``design``.

    See the module notes for the mapping. A design without segments (taps only) gets a silent
    amplitude envelope over its duration to carry the emphasis.

    Raises
    ------
    ClipError
        The design is longer than :data:`MAX_TIME_S` or needs more than :data:`MAX_BREAKPOINTS`.
    """
    if design.duration_s > MAX_TIME_S:
        raise ClipError(f"a .haptic file holds at most {MAX_TIME_S:g} s; this design lasts {design.duration_s:g} s")
    segments = design.segments or (Segment(0.0, max(design.duration_s, 0.0), 0.0, 0.0, 0.5, 0.5),)
    amplitude = _with_emphasis(_breakpoints(segments, "i0", "i1"), design.taps)
    frequency = [{"time": t, "frequency": v} for t, v in _breakpoints(segments, "s0", "s1")]
    if len(amplitude) + len(frequency) > MAX_BREAKPOINTS:
        raise ClipError(f"the design needs more than {MAX_BREAKPOINTS:,} breakpoints; a .haptic reader takes no more")
    metadata: dict[str, Any] = {"editor": "vibsynth", "description": description or design.description}
    if source:
        metadata["source"] = source
    if design.tags:
        metadata["tags"] = list(design.tags)
    return {
        "version": {"major": 1, "minor": 0, "patch": 0},
        "metadata": metadata,
        "signals": {"continuous": {"envelopes": {"amplitude": amplitude, "frequency": frequency}}},
    }


def meta_haptic_text(design: HapticDesign, *, description: str = "", source: str = "") -> str:
    """``.haptic`` JSON text of a design (see :func:`meta_haptic_data`)."""
    data = meta_haptic_data(design, description=description, source=source)
    return json.dumps(data, indent=2, allow_nan=False) + "\n"
