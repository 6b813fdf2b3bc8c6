"""Apple Haptic and Audio Pattern (AHAP) files: read into a :class:`HapticDesign`, write from one.

What is read (Apple's "Representing haptic patterns in AHAP files")::

    {"Version": 1.0, "Metadata": {...},
     "Pattern": [
       {"Event": {"Time": 0.0, "EventType": "HapticTransient",
                  "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.8},
                                      {"ParameterID": "HapticSharpness", "ParameterValue": 0.4}]}},
       {"Event": {"Time": 0.015, "EventType": "HapticContinuous", "EventDuration": 0.25, ...}},
       {"ParameterCurve": {"ParameterID": "HapticIntensityControl", "Time": 0.015,
                           "ParameterCurveControlPoints": [{"Time": 0, "ParameterValue": 1}, ...]}},
       {"Parameter": {"ParameterID": "HapticSharpnessControl", "Time": 0.3, "ParameterValue": -0.2}}]}

Semantics, as Core Haptics plays them: times in seconds; a missing HapticIntensity is 1 and a
missing HapticSharpness 0.5; the intensity control (0..1) *multiplies* every event's intensity,
the sharpness control (-1..1) is *added* to every event's sharpness, results clamped to 0..1.
A parameter curve interpolates linearly between its points and its last value holds until the
next curve or parameter of the same control (the latest one to start is in force). Where
continuous events overlap, the stronger one is felt. Out-of-range values are clamped, as Core
Haptics does (and reported in :attr:`HapticDesign.ignored`).

Not carried (reported, never an error): audio events, the envelope parameters (HapticAttackTime,
HapticDecayTime, HapticReleaseTime, Sustained) and their controls, unknown keys.
"""

from __future__ import annotations

import json
import os
from bisect import bisect_left, bisect_right
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vibsynth.errors import ClipError
from vibsynth.formats.files import atomic_write
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap
from vibsynth.formats.jsonio import JsonFields, JsonPath, json_shape, load_json, parse_json

__all__ = [
    "MAX_AHAP_BYTES",
    "MAX_PATTERN_ENTRIES",
    "MAX_CONTROL_POINTS",
    "MAX_TIME_S",
    "CURVE_POINTS",
    "TAP_HOLD_S",
    "read_ahap",
    "parse_ahap",
    "ahap_data",
    "ahap_text",
    "write_ahap",
]

#: AHAP files over this size are refused before they are read (a long designed pattern is ~100 KB).
MAX_AHAP_BYTES = 4 << 20
#: Most entries (events, curves, parameters) in a pattern.
MAX_PATTERN_ENTRIES = 10_000
#: Most parameter-curve control points in a pattern (all curves together).
MAX_CONTROL_POINTS = 100_000
#: Latest time an event may start or end: a clip holds at most 10 minutes.
MAX_TIME_S = 600.0
#: Core Haptics takes at most this many control points per parameter curve (the writer splits longer ones).
CURVE_POINTS = 16
WHAT = "an AHAP file"

_HAPTIC_EVENTS = ("HapticTransient", "HapticContinuous")
_AUDIO_EVENTS = ("AudioCustom", "AudioContinuous")
_INTENSITY, _SHARPNESS = "HapticIntensityControl", "HapticSharpnessControl"
_KEYS = {
    (): {"Version", "Metadata", "Pattern"},
    ("Pattern",): {"Event", "ParameterCurve", "Parameter"},
    ("Pattern", "Event"): {
        "Time",
        "EventType",
        "EventDuration",
        "EventParameters",
        "EventWaveformPath",
        "EventWaveformUseVolumeEnvelope",
        "EventWaveformLoopEnabled",
    },
    ("Pattern", "Event", "EventParameters"): {"ParameterID", "ParameterValue"},
    ("Pattern", "ParameterCurve"): {"ParameterID", "Time", "ParameterCurveControlPoints"},
    ("Pattern", "ParameterCurve", "ParameterCurveControlPoints"): {"Time", "ParameterValue"},
    ("Pattern", "Parameter"): {"ParameterID", "Time", "ParameterValue"},
}


class _Reader(JsonFields):
    """AHAP fields: Core Haptics clamps out-of-range values, and so does this reader (noting it)."""

    def __init__(self, origin: str) -> None:
        super().__init__(origin, _KEYS, ClipError)
        self.notes: dict[str, int] = {}

    def note(self, phrase: str) -> None:
        self.notes[phrase] = self.notes.get(phrase, 0) + 1

    def clamped(self, value: Any, path: JsonPath, low: float, high: float) -> float:
        x = self.number(value, path)
        if not low <= x <= high:
            self.note(f"{json_shape(path)} clamped to [{low:g}, {high:g}]")
        return min(max(x, low), high)

    def time(self, value: Any, path: JsonPath) -> float:
        return self.number(value, path, 0.0, MAX_TIME_S)

    def phrases(self) -> tuple[str, ...]:
        found = [f"unknown field {u}" for u in self.unknown]
        return tuple(found + [f"{p} (x{n})" if n > 1 else p for p, n in self.notes.items()])


@dataclass
class _Control:
    """One dynamic parameter (intensity or sharpness control) over time: curves and steps."""

    default: float
    sources: list[tuple[float, list[float], list[float]]] = field(default_factory=list)  # (start, times, values)
    starts: list[float] = field(default_factory=list)  # the sources' starts, once frozen

    def add(self, start: float, times: list[float], values: list[float]) -> None:
        self.sources.append((_snap(start), [_snap(t) for t in times], values))

    def freeze(self) -> None:
        """Order the sources (before any :meth:`value`)."""
        self.sources.sort(key=lambda s: s[0])  # stable: at equal starts the later entry of the file wins
        self.starts = [s[0] for s in self.sources]

    def value(self, t: float, *, left: bool = False) -> float:
        """The control at ``t`` (``left``: just before ``t``, excluding a source starting at ``t``)."""
        k = (bisect_left(self.starts, t) if left else bisect_right(self.starts, t)) - 1
        if k < 0:
            return self.default
        _, times, values = self.sources[k]
        if t >= times[-1]:
            return values[-1]
        j = bisect_right(times, t) - 1
        if j < 0:
            return values[0]
        u = (t - times[j]) / (times[j + 1] - times[j])
        return values[j] + u * (values[j + 1] - values[j])

    def times(self) -> Iterable[float]:
        for _, times, _ in self.sources:
            yield from times


def _snap(t: float) -> float:
    """Times to 0.1 us: ``Time + point Time`` sums that should meet (curves split in a row) do."""
    return round(t, 7)


@dataclass(frozen=True)
class _Event:
    t0: float
    t1: float
    intensity: float
    sharpness: float


def _event(r: _Reader, raw: Any, path: JsonPath, out: dict[str, list[Any]]) -> None:
    event = r.mapping(raw, path)
    kind = event.get("EventType")
    if kind in _AUDIO_EVENTS:
        r.note(f"{kind} events (audio is not played)")
        return
    if kind not in _HAPTIC_EVENTS:
        raise r.fail(
            path + ("EventType",),
            f"= {kind!r}: not an event type (allowed: {', '.join(_HAPTIC_EVENTS + _AUDIO_EVENTS)})",
        )
    if "Time" not in event:
        raise r.fail(path, "missing key 'Time'")
    t = r.time(event["Time"], path + ("Time",))
    values = {"HapticIntensity": 1.0, "HapticSharpness": 0.5}  # Core Haptics' defaults
    for j, raw_param in enumerate(r.items(event.get("EventParameters", []), path + ("EventParameters",))):
        ppath = path + ("EventParameters", j)
        param = r.mapping(raw_param, ppath)
        pid = param.get("ParameterID")
        if pid in values:
            if "ParameterValue" not in param:
                raise r.fail(ppath, "missing key 'ParameterValue'")
            values[pid] = r.clamped(param["ParameterValue"], ppath + ("ParameterValue",), 0.0, 1.0)
        elif isinstance(pid, str):
            r.note(f"event parameter {pid} (not applied)")
        else:
            raise r.fail(ppath + ("ParameterID",), f"= {pid!r}: must be a parameter name")
    if kind == "HapticTransient":
        out["taps"].append(Tap(_snap(t), values["HapticIntensity"], values["HapticSharpness"]))
        return
    if "EventDuration" not in event:
        raise r.fail(path, "missing key 'EventDuration' (a HapticContinuous event needs one)")
    duration = r.number(event["EventDuration"], path + ("EventDuration",), 0.0, MAX_TIME_S)
    if t + duration > MAX_TIME_S:
        raise r.fail(path, f"ends at {t + duration:g} s, after the {MAX_TIME_S:g} s a clip can hold")
    if _snap(t + duration) > _snap(t):
        out["events"].append(
            _Event(_snap(t), _snap(t + duration), values["HapticIntensity"], values["HapticSharpness"])
        )


def _control_range(pid: str) -> tuple[float, float]:
    return (0.0, 1.0) if pid == _INTENSITY else (-1.0, 1.0)


def _control_id(
    r: _Reader, body: dict[str, Any], path: JsonPath, controls: dict[str, _Control], what: str
) -> str | None:
    """The control a curve or parameter sets; None (noted) for one vibsynth does not apply."""
    pid = body.get("ParameterID")
    if pid in controls:
        return str(pid)
    if not isinstance(pid, str):
        raise r.fail(path + ("ParameterID",), f"= {pid!r}: must be a parameter name")
    r.note(f"{what} of {pid} (not applied)")
    return None


def _curve(r: _Reader, raw: Any, path: JsonPath, controls: dict[str, _Control], budget: list[int]) -> None:
    curve = r.mapping(raw, path)
    pid = _control_id(r, curve, path, controls, "parameter curves")
    if pid is None:
        return
    start = r.time(r.require(curve, "Time", path), path + ("Time",))
    points = r.items(curve.get("ParameterCurveControlPoints"), path + ("ParameterCurveControlPoints",))
    if not points:
        raise r.fail(path + ("ParameterCurveControlPoints",), "is empty (a curve needs at least one point)")
    budget[0] -= len(points)
    if budget[0] < 0:
        raise r.fail(("Pattern",), f"holds more than {MAX_CONTROL_POINTS:,} parameter-curve control points")
    low, high = _control_range(pid)
    times: list[float] = []
    values: list[float] = []
    for j, raw_point in enumerate(points):
        ppath = path + ("ParameterCurveControlPoints", j)
        point = r.mapping(raw_point, ppath)
        for key in ("Time", "ParameterValue"):
            if key not in point:
                raise r.fail(ppath, f"missing key {key!r}")
        t = start + r.time(point["Time"], ppath + ("Time",))
        if t > MAX_TIME_S:
            raise r.fail(ppath + ("Time",), f"ends at {t:g} s, after the {MAX_TIME_S:g} s a clip can hold")
        if times and t < times[-1]:
            raise r.fail(ppath + ("Time",), f"= {point['Time']!r}: control point times must not decrease")
        if times and _snap(t) <= _snap(times[-1]):
            t = times[-1] + 1e-7  # a step inside a curve: keep the times strictly increasing
        times.append(t)
        values.append(r.clamped(point["ParameterValue"], ppath + ("ParameterValue",), low, high))
    controls[pid].add(times[0], times, values)


def _parameter(r: _Reader, raw: Any, path: JsonPath, controls: dict[str, _Control]) -> None:
    param = r.mapping(raw, path)
    pid = _control_id(r, param, path, controls, "dynamic parameters")
    if pid is None:
        return
    for key in ("Time", "ParameterValue"):
        r.require(param, key, path)
    t = r.time(param["Time"], path + ("Time",))
    low, high = _control_range(pid)
    controls[pid].add(t, [t], [r.clamped(param["ParameterValue"], path + ("ParameterValue",), low, high)])


def _design(events: list[_Event], taps: list[Tap], ic: _Control, sc: _Control, r: _Reader, meta: Any) -> HapticDesign:
    duration = max([e.t1 for e in events] + [t.t for t in taps])
    cuts = {0.0, duration}
    cuts.update(e.t0 for e in events)
    cuts.update(e.t1 for e in events)
    cuts.update(t for t in ic.times() if t < duration)
    cuts.update(t for t in sc.times() if t < duration)
    cuts.update(s[0] for s in ic.sources + sc.sources if s[0] < duration)
    edges = sorted(c for c in cuts if 0 <= c <= duration)
    segments: list[Segment] = []
    sharp = 0.5
    by_start = sorted(events, key=lambda e: e.t0)
    active: list[_Event] = []
    k = 0
    for a, b in zip(edges, edges[1:]):  # sweep: every event start and end is an edge
        while k < len(by_start) and by_start[k].t0 <= a:
            active.append(by_start[k])
            k += 1
        active = [e for e in active if e.t1 > a]
        if not active:
            segments.append(Segment(a, b, 0.0, 0.0, sharp, sharp))
            continue
        top = max(active, key=lambda e: e.intensity)
        i0, i1 = top.intensity * ic.value(a), top.intensity * ic.value(b, left=True)
        s0, s1 = top.sharpness + sc.value(a), top.sharpness + sc.value(b, left=True)
        segments.extend(_clamped(Segment(a, b, i0, i1, s0, s1)))
        sharp = segments[-1].s1
    design_taps = tuple(
        Tap(t.t, min(1.0, t.intensity * ic.value(t.t)), min(1.0, max(0.0, t.sharpness + sc.value(t.t))))
        for t in sorted(taps, key=lambda t: t.t)
    )
    description = meta.get("Description", "") if isinstance(meta, dict) else ""
    return HapticDesign(
        tuple(_merged(segments)),
        design_taps,
        duration,
        description=description if isinstance(description, str) else "",
        ignored=r.phrases(),
    )


def _clamped(seg: Segment) -> list[Segment]:
    """Split a segment where its sharpness leaves 0..1 and clamp it there (as Core Haptics does)."""
    cuts = [seg.t0, seg.t1]
    for edge in (0.0, 1.0):
        if (seg.s0 - edge) * (seg.s1 - edge) < 0:
            cuts.append(seg.t0 + (edge - seg.s0) / (seg.s1 - seg.s0) * (seg.t1 - seg.t0))
    cuts.sort()
    out = []
    for a, b in zip(cuts, cuts[1:]):
        if b <= a:
            continue
        ia, sa = seg.at(a) if a > seg.t0 else (seg.i0, seg.s0)
        ib, sb = seg.at(b) if b < seg.t1 else (seg.i1, seg.s1)
        out.append(Segment(a, b, ia, ib, min(1.0, max(0.0, sa)), min(1.0, max(0.0, sb))))
    return out


def _merged(segments: list[Segment]) -> list[Segment]:
    """Join neighbouring constant segments of equal value (an event split by a control point nothing changed)."""
    out: list[Segment] = []
    for seg in segments:
        last = out[-1] if out else None
        if last is not None and last.constant and seg.constant and (last.i0, last.s0) == (seg.i0, seg.s0):
            out[-1] = Segment(last.t0, seg.t1, seg.i0, seg.i0, seg.s0, seg.s0)
        else:
            out.append(seg)
    return out


def _from_data(data: Any, origin: str) -> HapticDesign:
    r = _Reader(origin)
    root = r.mapping(data, ())
    version = root.get("Version", 1)
    if isinstance(version, bool) or not isinstance(version, (int, float)) or version != 1:
        raise r.fail(("Version",), f"= {version!r}: this vibsynth reads AHAP version 1")
    if "Pattern" not in root:
        raise r.fail((), "missing key 'Pattern' (the list of events and curves)")
    pattern = r.items(root["Pattern"], ("Pattern",))
    if len(pattern) > MAX_PATTERN_ENTRIES:
        raise r.fail(("Pattern",), f"has {len(pattern):,} entries (allowed: at most {MAX_PATTERN_ENTRIES:,})")
    out: dict[str, list[Any]] = {"events": [], "taps": []}
    controls = {_INTENSITY: _Control(1.0), _SHARPNESS: _Control(0.0)}
    budget = [MAX_CONTROL_POINTS]
    for i, raw in enumerate(pattern):
        entry = r.mapping(raw, ("Pattern", i))
        kinds = [k for k in ("Event", "ParameterCurve", "Parameter") if k in entry]
        if len(kinds) != 1:
            raise r.fail(("Pattern", i), "must hold exactly one of Event, ParameterCurve, Parameter")
        kind = kinds[0]
        path: JsonPath = ("Pattern", i, kind)
        if kind == "Event":
            _event(r, entry[kind], path, out)
        elif kind == "ParameterCurve":
            _curve(r, entry[kind], path, controls, budget)
        else:
            _parameter(r, entry[kind], path, controls)
    if not out["events"] and not out["taps"]:
        raise r.fail(("Pattern",), "holds no haptic event (HapticTransient or HapticContinuous)")
    for control in controls.values():
        control.freeze()
    return _design(out["events"], out["taps"], controls[_INTENSITY], controls[_SHARPNESS], r, root.get("Metadata"))


def parse_ahap(text: str, origin: str = "<ahap>") -> HapticDesign:
    """Parse AHAP text (JSON) into a design.

    Raises
    ------
    ClipError
        Not JSON (truncated, NaN, too deep or large), not an AHAP pattern, a value of the wrong
        type, times out of order or beyond 10 minutes, too many entries: one line naming the
        file and the JSON path (``x.ahap: Pattern[3].Event.Time = -1: outside the allowed range``).
    """
    return _from_data(parse_json(text, origin, error=ClipError), origin)


def read_ahap(path: str | os.PathLike[str]) -> HapticDesign:
    """Read an AHAP file (at most :data:`MAX_AHAP_BYTES`, refused before reading); see :func:`parse_ahap`."""
    p = Path(path)
    return _from_data(load_json(p, error=ClipError, what=WHAT, max_bytes=MAX_AHAP_BYTES), str(p))


# --------------------------------------------------------------------------- writing
def _r(x: float) -> float:
    """Times and values as written: 6 decimals (a microsecond), no ``-0.0``."""
    return round(float(x), 6) + 0.0


def _param(pid: str, value: float) -> dict[str, Any]:
    return {"ParameterID": pid, "ParameterValue": _r(value)}


def _continuous(t0: float, t1: float, intensity: float, sharpness: float) -> dict[str, Any]:
    return {
        "Event": {
            "Time": _r(t0),
            "EventType": "HapticContinuous",
            "EventDuration": _r(t1 - t0),
            "EventParameters": [_param("HapticIntensity", intensity), _param("HapticSharpness", sharpness)],
        }
    }


def _curves(pid: str, points: list[tuple[float, float]]) -> list[dict[str, Any]]:
    """Parameter curves of at most :data:`CURVE_POINTS` points each, one after the other."""
    out = []
    k = 0
    while k < len(points) - 1 or (k == 0 and points):
        chunk = points[k : k + CURVE_POINTS]
        start = chunk[0][0]
        out.append(
            {
                "ParameterCurve": {
                    "ParameterID": pid,
                    "Time": _r(start),
                    "ParameterCurveControlPoints": [{"Time": _r(t - start), "ParameterValue": _r(v)} for t, v in chunk],
                }
            }
        )
        k += CURVE_POINTS - 1  # the next curve starts at this one's last point
        if len(chunk) < CURVE_POINTS:
            break
    return out


def _runs(segments: Sequence[Segment]) -> Iterable[list[Segment]]:
    """Constant segments one by one; non-constant ones in runs that are continuous at their joins."""
    run: list[Segment] = []
    for seg in segments:
        if seg.constant:
            if run:
                yield run
                run = []
            yield [seg]
        elif run and (run[-1].i1, run[-1].s1, run[-1].t1) == (seg.i0, seg.s0, seg.t0):
            run.append(seg)
        else:
            if run:
                yield run
            run = [seg]
    if run:
        yield run


#: A tap inside a sloped stretch gets this much constant signal around it (see :func:`ahap_data`).
TAP_HOLD_S = 1e-4


def _split_at_taps(segments: Sequence[Segment], taps: Sequence[Tap]) -> list[Segment]:
    """Cut sloped segments at tap times into a :data:`TAP_HOLD_S` constant piece, so that no control
    curve is in force at a tap (Core Haptics would scale the tap by it too)."""
    out = list(segments)
    for tap in taps:
        for k, seg in enumerate(out):
            if seg.constant or not seg.t0 <= tap.t < seg.t1:
                continue
            end = min(seg.t1, tap.t + TAP_HOLD_S)
            i, s = seg.at(tap.t) if tap.t > seg.t0 else (seg.i0, seg.s0)
            pieces = [Segment(tap.t, end, i, i, s, s)]
            if tap.t > seg.t0:
                pieces.insert(0, Segment(seg.t0, tap.t, seg.i0, i, seg.s0, s))
            if end < seg.t1:
                ie, se = seg.at(end)
                pieces.append(Segment(end, seg.t1, ie, seg.i1, se, seg.s1))
            out[k : k + 1] = pieces
            break
    return out


def ahap_data(design: HapticDesign, *, description: str = "") -> dict[str, Any]:
    """AHAP (as plain data) that Core Haptics plays like the design, and :func:`parse_ahap` reads back.

    A constant stretch becomes a HapticContinuous event; a sloped run becomes one event at the run's
    peak intensity shaped by intensity and sharpness control curves (split every
    :data:`CURVE_POINTS` points); both controls are reset by dynamic parameters where the run ends.
    Taps become HapticTransient events at their own values: a sloped stretch is held constant for
    :data:`TAP_HOLD_S` at a tap so that no control scales it.
    """
    pattern: list[dict[str, Any]] = []
    ic, sc = _Control(1.0), _Control(0.0)
    for run in _runs(_split_at_taps(design.segments, design.taps)):
        first, last = run[0], run[-1]
        if first.constant:
            if first.i0 > 0:
                pattern.append(_continuous(first.t0, first.t1, first.i0, first.s0))
            continue
        peak = max(max(s.i0, s.i1) for s in run)
        if peak <= 0:
            continue
        base = first.s0
        times = [first.t0] + [s.t1 for s in run]
        ivals = [first.i0 / peak] + [s.i1 / peak for s in run]
        svals = [0.0] + [s.s1 - base for s in run]
        pattern.append(_continuous(first.t0, last.t1, peak, base))
        for pid, values, reset, control in ((_INTENSITY, ivals, 1.0, ic), (_SHARPNESS, svals, 0.0, sc)):
            for entry in _curves(pid, list(zip(times, values))):
                pattern.append(entry)
                curve = entry["ParameterCurve"]
                pts = curve["ParameterCurveControlPoints"]
                control.add(curve["Time"], [curve["Time"] + p["Time"] for p in pts], [p["ParameterValue"] for p in pts])
            end = _r(last.t1)  # back to the events' own values
            pattern.append({"Parameter": {"ParameterID": pid, "Time": end, "ParameterValue": reset}})
            control.add(end, [end], [reset])
    ic.freeze()
    sc.freeze()
    for tap in design.taps:
        at = _snap(_r(tap.t))  # where a reader will see it
        gain, offset = ic.value(at), sc.value(at)  # 1 and 0 unless two taps share a slope's hold
        pattern.append(
            {
                "Event": {
                    "Time": _r(tap.t),
                    "EventType": "HapticTransient",
                    "EventParameters": [
                        _param("HapticIntensity", min(1.0, tap.intensity / gain) if gain > 0 else tap.intensity),
                        _param("HapticSharpness", min(1.0, max(0.0, tap.sharpness - offset))),
                    ],
                }
            }
        )
    pattern.sort(key=_entry_time)
    metadata = {"Project": "vibsynth", "Description": description or design.description}
    return {"Version": 1.0, "Metadata": metadata, "Pattern": pattern}


def _entry_time(entry: dict[str, Any]) -> float:
    body = next(iter(entry.values()))
    return float(body["Time"])


def ahap_text(design: HapticDesign, *, description: str = "") -> str:
    """AHAP JSON text of a design (see :func:`ahap_data`)."""
    return json.dumps(ahap_data(design, description=description), indent=2, allow_nan=False) + "\n"


def write_ahap(design: HapticDesign, path: str | os.PathLike[str], *, description: str = "") -> Path:
    """Write a design as an AHAP file, atomically; returns the path."""
    target = Path(path)
    try:
        atomic_write(target, ahap_text(design, description=description))
    except OSError as exc:
        raise ClipError(f"{target}: cannot write ({exc.strerror})") from None
    return target
