"""AHAP (Apple Core Haptics): continuous and transient events, parameter curves and dynamic parameters as
Core Haptics applies them, what is ignored, every refused file, and the writer read back."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.formats.haptic_samples import ahap, curve, event
from vibsynth.errors import ClipError
from vibsynth.formats.ahap import (
    CURVE_POINTS,
    MAX_AHAP_BYTES,
    MAX_PATTERN_ENTRIES,
    ahap_data,
    ahap_text,
    parse_ahap,
    read_ahap,
    write_ahap,
)
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap

# Apple's "spring" example: a transient, a continuous event shaped by an intensity and a sharpness curve
BOING = ahap(
    event(0.0, "HapticTransient", intensity=0.8, sharpness=0.4),
    event(0.015, duration=0.25, intensity=0.8, sharpness=0.4),
    curve("HapticIntensityControl", 0.015, [(0, 1), (0.1, 0.5), (0.25, 0.0)]),
    curve("HapticSharpnessControl", 0.015, [(0, 0.0), (0.25, -0.3)]),
)


def test_continuous_transient_and_curves_as_core_haptics_plays_them():
    d = parse_ahap(BOING, "boing.ahap")
    assert d.duration_s == pytest.approx(0.265) and not d.ignored
    assert d.taps == (Tap(0.0, 0.8, 0.4),)  # before the curves start: controls at 1 and 0
    assert d.value_at(0.005) == (0.0, 0.5)  # nothing plays before the continuous event
    i, s = d.value_at(0.015 + 0.05)  # half way to the curve's second point: control 0.75
    assert i == pytest.approx(0.8 * 0.75) and s == pytest.approx(0.4 - 0.3 * 0.05 / 0.25)
    i, s = d.value_at(0.015 + 0.175)  # control 0.25, sharpness offset -0.21
    assert i == pytest.approx(0.8 * 0.25) and s == pytest.approx(0.4 - 0.3 * 0.175 / 0.25)
    assert d.value_at(0.265)[0] == pytest.approx(0.0)


def test_intensity_control_also_scales_transients_and_sharpness_control_offsets_them():
    d = parse_ahap(
        ahap(
            event(0.2, "HapticTransient", intensity=0.8, sharpness=0.5),
            curve("HapticIntensityControl", 0.0, [(0, 1.0), (0.4, 0.0)]),
            curve("HapticSharpnessControl", 0.0, [(0, 0.0), (0.4, 0.4)]),
        )
    )
    assert d.taps[0].intensity == pytest.approx(0.4) and d.taps[0].sharpness == pytest.approx(0.7)


def test_dynamic_parameters_step_and_the_latest_control_is_in_force():
    d = parse_ahap(
        ahap(
            event(0.0, duration=1.0, intensity=1.0, sharpness=0.5),
            {"Parameter": {"ParameterID": "HapticIntensityControl", "Time": 0.5, "ParameterValue": 0.25}},
            curve("HapticSharpnessControl", 0.2, [(0, 0.2), (0.1, 0.2)]),  # holds its last value after 0.3 s
        )
    )
    assert d.value_at(0.1) == (1.0, 0.5)
    assert d.value_at(0.25) == pytest.approx((1.0, 0.7))
    assert d.value_at(0.4) == pytest.approx((1.0, 0.7))
    assert d.value_at(0.6) == pytest.approx((0.25, 0.7))  # the step at 0.5 s


def test_overlapping_events_the_stronger_is_felt_and_defaults_apply():
    d = parse_ahap(
        ahap(
            event(0.0, duration=1.0, intensity=0.3, sharpness=0.1),
            event(0.4, duration=0.2),  # no parameters: intensity 1, sharpness 0.5 (Core Haptics' defaults)
        )
    )
    assert d.value_at(0.2) == (0.3, 0.1) and d.value_at(0.5) == (1.0, 0.5) and d.value_at(0.8) == (0.3, 0.1)


def test_sharpness_leaving_0_1_is_clamped_where_it_crosses():
    d = parse_ahap(
        ahap(
            event(0.0, duration=1.0, intensity=1.0, sharpness=0.6),
            curve("HapticSharpnessControl", 0.0, [(0, 0.0), (1.0, 0.8)]),
        )
    )
    assert d.value_at(0.5)[1] == pytest.approx(1.0)  # 0.6 + 0.4 = 1.0: the edge is a segment boundary
    assert d.value_at(0.9)[1] == 1.0 and d.value_at(0.25)[1] == pytest.approx(0.8)
    assert [seg.t0 for seg in d.segments] == pytest.approx([0.0, 0.5])


def test_what_is_not_carried_is_listed_once_each():
    d = parse_ahap(
        ahap(
            event(0.0, "AudioCustom", EventWaveformPath="a.wav"),
            event(0.1, "AudioCustom", EventWaveformPath="b.wav"),
            event(0.0, duration=0.5, intensity=1.5, sharpness=0.5, Colour="red"),
            {
                "Event": {
                    "Time": 0.2,
                    "EventType": "HapticTransient",
                    "Extra": 1,
                    "EventParameters": [{"ParameterID": "HapticAttackTime", "ParameterValue": 0.1}],
                }
            },
            curve("AudioVolumeControl", 0.0, [(0, 1)]),
            Foo={"bar": 1},
        )
    )
    assert d.ignored == (
        "unknown field Foo",
        "unknown field Pattern[].Event.Colour",
        "unknown field Pattern[].Event.Extra",
        "AudioCustom events (audio is not played) (x2)",
        "Pattern[].Event.EventParameters[].ParameterValue clamped to [0, 1]",
        "event parameter HapticAttackTime (not applied)",
        "parameter curves of AudioVolumeControl (not applied)",
    )
    assert d.value_at(0.1)[0] == 1.0  # clamped, as Core Haptics does


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"Version": 1, "Pattern": [{"Event": {"Time": 0.0, "EventType": "Hap', "x.ahap:1:"),
        ('{"Pattern": [{"Event": {"Time": NaN, "EventType": "HapticTransient"}}]}', "NaN is not a number"),
        ('{"Pattern": [{"Event": {"Time": 1e999, "EventType": "HapticTransient"}}]}', "1e999 is too large"),
        (ahap(event(-1, "HapticTransient")), "x.ahap: Pattern[0].Event.Time = -1: outside the allowed range [0, 600]"),
        (ahap(event(700, "HapticTransient")), "x.ahap: Pattern[0].Event.Time = 700: outside the allowed range"),
        (ahap(event(0, duration=601)), "Pattern[0].Event.EventDuration = 601: outside the allowed range"),
        (ahap(event(500, duration=200)), "Pattern[0].Event: ends at 700 s, after the 600 s a clip can hold"),
        (ahap(event("0", "HapticTransient")), 'Pattern[0].Event.Time = "0": must be a number'),
        (ahap(event(0, "HapticBuzz")), "Pattern[0].Event.EventType = 'HapticBuzz': not an event type"),
        (ahap(event(0)), "Pattern[0].Event: missing key 'EventDuration'"),
        (ahap({"Event": {"EventType": "HapticTransient"}}), "Pattern[0].Event: missing key 'Time'"),
        (ahap({"Event": {}, "Parameter": {}}), "Pattern[0]: must hold exactly one of Event, ParameterCurve, Parameter"),
        (ahap(curve("HapticIntensityControl", 0, [(0.2, 1), (0.1, 0)])), "ParameterCurveControlPoints[1].Time = 0.1: "),
        (ahap(curve("HapticIntensityControl", 0, [])), "ParameterCurveControlPoints: is empty"),
        (ahap(event(0, "AudioCustom")), "x.ahap: Pattern: holds no haptic event"),
        (ahap(event(0, "HapticTransient"), Version=2), "x.ahap: Version = 2: this vibsynth reads AHAP version 1"),
        ('{"Version": 1}', "x.ahap: missing key 'Pattern'"),
        ('{"Pattern": {}}', "x.ahap: Pattern: must be a list, got an object"),
        ("[1, 2]", "x.ahap: must be an object, got a list"),
        ('{"Pattern": [], "Pattern": []}', "key 'Pattern' appears twice"),
    ],
)
def test_each_malformed_file_gets_one_clear_error(text, message):
    with pytest.raises(ClipError) as info:
        parse_ahap(text, "x.ahap")
    assert message in str(info.value) and "\n" not in str(info.value)


def test_entry_and_control_point_counts_are_capped():
    many = ahap(*[event(0.0, "HapticTransient")] * (MAX_PATTERN_ENTRIES + 1))
    with pytest.raises(ClipError, match=r"Pattern: has 10,001 entries \(allowed: at most 10,000\)"):
        parse_ahap(many, "x.ahap")
    points = [(k * 1e-4, 1.0) for k in range(20_000)]
    dense = ahap(event(0, "HapticTransient"), *[curve("HapticIntensityControl", 0, points)] * 6)
    with pytest.raises(ClipError, match=r"holds more than 100,000 parameter-curve control points"):
        parse_ahap(dense, "x.ahap")


def test_a_million_events_and_huge_files_are_refused_before_parsing(tmp_path):
    path = tmp_path / "million.ahap"
    one = json.dumps(event(0.0, "HapticTransient")) + ","
    path.write_text('{"Pattern": [' + one * 1_000_000 + "]}")
    with pytest.raises(ClipError) as info:
        read_ahap(path)
    assert str(info.value).startswith(f"{path}: ") and "over the 4 MiB limit for an AHAP file; not read" in str(
        info.value
    )
    assert path.stat().st_size > MAX_AHAP_BYTES


# --------------------------------------------------------------------------- writing
def test_writer_keeps_constant_events_and_transients_exactly(tmp_path):
    design = HapticDesign(
        (
            Segment(0.0, 0.1, 0.0, 0.0, 0.5, 0.5),
            Segment(0.1, 0.4, 0.7, 0.7, 0.2, 0.2),
            Segment(0.4, 0.5, 0.0, 0.0, 0.2, 0.2),
            Segment(0.5, 0.7, 0.4, 0.4, 0.9, 0.9),
        ),
        (Tap(0.05, 0.9, 0.6), Tap(0.45, 0.5, 0.1)),
        0.7,
    )
    path = write_ahap(design, tmp_path / "x.ahap", description="two events")
    data = json.loads(path.read_text())
    assert data["Version"] == 1.0 and data["Metadata"]["Description"] == "two events"
    events = [e["Event"] for e in data["Pattern"]]
    assert [(e["Time"], e["EventType"], e.get("EventDuration")) for e in events] == [
        (0.05, "HapticTransient", None),
        (0.1, "HapticContinuous", 0.3),
        (0.45, "HapticTransient", None),
        (0.5, "HapticContinuous", 0.2),
    ]
    assert [[p["ParameterValue"] for p in e["EventParameters"]] for e in events] == [
        [0.9, 0.6],
        [0.7, 0.2],
        [0.5, 0.1],
        [0.4, 0.9],
    ]
    back = read_ahap(path)
    for t in np.linspace(0, 0.7, 141):
        assert back.value_at(float(t)) == pytest.approx(design.value_at(float(t))) or design.value_at(float(t))[0] == 0
    assert back.taps == design.taps


def test_writer_ramps_use_curves_split_every_16_points_and_read_back_the_same():
    rng = np.random.default_rng(16)
    knots = np.r_[0.0, np.cumsum(rng.uniform(0.005, 0.02, 40))]
    values = rng.uniform(0.05, 1.0, (41, 2))
    segments = tuple(
        Segment(
            float(knots[k]), float(knots[k + 1]), *values[k, :1], *values[k + 1, :1], *values[k, 1:], *values[k + 1, 1:]
        )
        for k in range(40)
    )  # continuous at every join: one run
    times = knots[1:]
    design = HapticDesign(segments, (Tap(float(times[10]) + 0.001, 0.8, 0.3),), float(times[-1]))
    data = ahap_data(design)
    curves = [e["ParameterCurve"] for e in data["Pattern"] if "ParameterCurve" in e]
    assert all(len(c["ParameterCurveControlPoints"]) <= CURVE_POINTS for c in curves) and len(curves) >= 6
    back = parse_ahap(ahap_text(design), "x.ahap")
    for t in rng.uniform(0, float(times[-1]), 300):
        got, want = back.value_at(float(t)), design.value_at(float(t))
        assert got == pytest.approx(want, abs=0.01), t
    assert back.taps[0].intensity == pytest.approx(0.8) and back.taps[0].sharpness == pytest.approx(0.3)
