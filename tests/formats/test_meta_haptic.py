"""Meta Haptics Studio ``.haptic`` (the Lofelt data model v1): envelopes, emphasis, steps, ignored keys, refusals;
writing, and the round trip clip -> .haptic -> clip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.formats.haptic_samples import meta
from vibsynth.errors import ClipError
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap
from vibsynth.formats.meta_haptic import (
    MAX_HAPTIC_BYTES,
    meta_haptic_data,
    meta_haptic_text,
    parse_meta_haptic,
    read_meta_haptic,
)
from vibsynth.settings.clip_convert import ClipMapping, clip_from_design, design_from_clip
from vibsynth.settings.clips import load_clip_library

# shaped like the published example (valid_v1.haptic of the Lofelt SDK): an emphasis on the third breakpoint
EXAMPLE = meta(
    [
        {"time": 0.0, "amplitude": 0.2},
        {"time": 0.1, "amplitude": 0.3},
        {"time": 0.2, "amplitude": 0.2, "emphasis": {"amplitude": 0.6, "frequency": 0.7}},
        {"time": 0.3, "amplitude": 0.5},
        {"time": 1.0, "amplitude": 0.5},
    ],
    [{"time": 0.0, "frequency": 0.99}, {"time": 0.5, "frequency": 0.2}],
)


def test_envelopes_are_linear_and_emphasis_is_a_tap():
    d = parse_meta_haptic(EXAMPLE, "x.haptic")
    assert d.duration_s == 1.0 and d.description == "a test" and d.tags == ("test",) and not d.ignored
    assert d.taps == (Tap(0.2, 0.6, 0.7),)
    i, s = d.value_at(0.05)
    assert i == pytest.approx(0.25) and s == pytest.approx(0.99 - 0.79 * 0.1)
    i, s = d.value_at(0.25)
    assert i == pytest.approx(0.35) and s == pytest.approx(0.99 - 0.79 * 0.5)
    assert d.value_at(0.8) == pytest.approx((0.5, 0.2))  # frequency holds its last value


def test_equal_times_are_a_step_and_silence_before_the_first_amplitude_breakpoint():
    d = parse_meta_haptic(
        meta(
            [
                {"time": 0.1, "amplitude": 0.8},
                {"time": 0.3, "amplitude": 0.8},
                {"time": 0.3, "amplitude": 0.1},
                {"time": 0.5, "amplitude": 0.1},
            ]
        ),
        "x.haptic",
    )
    assert d.value_at(0.05) == (0.0, 0.5)  # silent; no frequency envelope: 0.5
    assert d.value_at(0.2) == (0.8, 0.5) and d.value_at(0.3) == (0.1, 0.5)
    before_step = [seg for seg in d.segments if seg.t1 == pytest.approx(0.3)][0]
    assert before_step.i1 == 0.8


def test_unknown_fields_are_listed():
    d = parse_meta_haptic(
        meta([{"time": 0.0, "amplitude": 0.5, "curve": "ease"}, {"time": 0.2, "amplitude": 0.0}], signals2=1),
        "x.haptic",
    )
    assert d.ignored == ("unknown field signals2", "unknown field signals.continuous.envelopes.amplitude[].curve")


@pytest.mark.parametrize(
    "text, message",
    [
        (meta([{"time": 0.0, "amplitude": 1.5}]), "amplitude[0].amplitude = 1.5: outside the allowed range [0, 1]"),
        (
            meta([{"time": 0.2, "amplitude": 0.1}, {"time": 0.1, "amplitude": 0.1}]),
            "amplitude[1].time = 0.1: breakpoint times must not decrease",
        ),
        (meta([{"time": 0.0}]), "amplitude[0]: missing key 'amplitude'"),
        (
            meta([{"time": 0.0, "amplitude": 0.1, "emphasis": {"amplitude": 0.5}}]),
            "emphasis: missing key 'frequency'",
        ),
        (
            meta([{"time": 0.0, "amplitude": 0.1, "emphasis": {"amplitude": 0.5, "frequency": 2}}]),
            "emphasis.frequency = 2: outside the allowed range [0, 1]",
        ),
        (meta([]), "envelopes.amplitude: is empty"),
        (meta([{"time": 0.0, "amplitude": 0.1}], [{"time": -1, "frequency": 0.1}]), "frequency[0].time = -1"),
        (meta([{"time": 0.0, "amplitude": 0.1}], version={"major": 2}), "version.major = 2: this vibsynth reads"),
        ('{"signals": {}}', "x.haptic: missing key 'version'"),
        ('{"version": {"major": 1}}', "x.haptic: missing key 'signals'"),
        (
            '{"version": {"major": 1}, "signals": {"continuous": {"envelopes": {"amplitude": [{"time": 0.1',
            "x.haptic:1:",
        ),
        (meta([{"time": float("nan"), "amplitude": 0.1}]), "NaN is not a number"),
    ],
)
def test_each_malformed_file_gets_one_clear_error(text, message):
    with pytest.raises(ClipError) as info:
        parse_meta_haptic(text, "x.haptic")
    assert message in str(info.value) and "\n" not in str(info.value) and str(info.value).startswith("x.haptic")


def test_huge_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "huge.haptic"
    point = json.dumps({"time": 0.0, "amplitude": 0.1}) + ","
    path.write_text(meta([])[:-4] + point * 200_000 + "]}}}}")
    assert path.stat().st_size > MAX_HAPTIC_BYTES
    with pytest.raises(ClipError, match=r"over the 4 MiB limit for a .haptic file; not read"):
        read_meta_haptic(path)


# --------------------------------------------------------------------------- writing
def _grid(duration_s: float, n: int = 997) -> list[float]:
    return [duration_s * k / n for k in range(n + 1)]


def test_written_file_reads_back_as_the_same_design_with_steps_slopes_and_taps():
    design = parse_meta_haptic(EXAMPLE, "x.haptic")
    stepped = parse_meta_haptic(
        meta(
            [
                {"time": 0.1, "amplitude": 0.8},
                {"time": 0.3, "amplitude": 0.8, "emphasis": {"amplitude": 0.9, "frequency": 0.1}},
                {"time": 0.3, "amplitude": 0.1},
                {"time": 0.5, "amplitude": 0.4},
            ],
            [{"time": 0.0, "frequency": 0.2}, {"time": 0.25, "frequency": 0.2}, {"time": 0.25, "frequency": 0.9}],
        ),
        "y.haptic",
    )
    for d in (design, stepped):
        back = parse_meta_haptic(meta_haptic_text(d), "back.haptic")
        assert back.duration_s == pytest.approx(d.duration_s) and back.taps == d.taps and not back.ignored
        for t in _grid(d.duration_s):
            assert back.value_at(t) == pytest.approx(d.value_at(t), abs=1e-6), t
    data = json.loads(meta_haptic_text(stepped))
    amplitude = data["signals"]["continuous"]["envelopes"]["amplitude"]
    times = [p["time"] for p in amplitude]
    assert times.count(0.3) == 2 and "emphasis" in amplitude[times.index(0.3) + 1]  # the step's right side
    assert data["metadata"]["editor"] == "vibsynth" and data["version"]["major"] == 1


def test_collinear_breakpoints_are_left_out_and_a_tap_adds_one_on_the_envelope():
    ramp = HapticDesign(
        (Segment(0.0, 0.5, 0.0, 0.5, 0.5, 0.5), Segment(0.5, 1.0, 0.5, 1.0, 0.5, 0.5)), (Tap(0.25, 0.1, 0.3),), 1.0
    )
    data = meta_haptic_data(ramp)
    amplitude = data["signals"]["continuous"]["envelopes"]["amplitude"]
    assert amplitude == [
        {"time": 0.0, "amplitude": 0.0},
        {"time": 0.25, "amplitude": 0.25, "emphasis": {"amplitude": 0.25, "frequency": 0.3}},  # raised to the curve
        {"time": 1.0, "amplitude": 1.0},
    ]
    assert data["signals"]["continuous"]["envelopes"]["frequency"] == [
        {"time": 0.0, "frequency": 0.5},
        {"time": 1.0, "frequency": 0.5},
    ]


def test_taps_only_design_keeps_its_taps_on_a_silent_envelope():
    design = HapticDesign((), (Tap(0.0, 0.7, 0.2), Tap(0.4, 0.5, 0.9), Tap(0.4, 0.6, 0.1)), 0.4)
    back = parse_meta_haptic(meta_haptic_text(design), "t.haptic")
    assert back.taps == (Tap(0.0, 0.7, 0.2), Tap(0.4, 0.6, 0.1))  # of two at one time the stronger
    assert back.value_at(0.2) == (0.0, 0.5)


@pytest.mark.parametrize("name", ["heartbeat", "impact", "zipper", "rain", "gravel-steps"])
def test_every_shipped_clip_survives_export_and_import(name):
    mapping = ClipMapping()
    clip = load_clip_library(None).get(name)
    text = meta_haptic_text(design_from_clip(clip, mapping))
    back = clip_from_design(parse_meta_haptic(text, f"{name}.haptic"), name, mapping)
    times = [clip.duration_ms * k / 2000 for k in range(2000)]  # a step at the very end lasts no time
    ends = [clip.duration_ms] + [t.t_ms + mapping.transient_decay_ms for t in clip.transients]  # decays kept whole
    assert back.duration_ms == pytest.approx(max(ends), abs=1e-3)
    assert np.max(np.abs(back.values_at(times) - clip.values_at(times))) < 0.005
    assert [round(t.t_ms, 3) for t in back.transients] == [round(t.t_ms, 3) for t in clip.transients]
    for a, b in zip(clip.transients, back.transients):  # what plays is max(curve, transient): unchanged
        assert max(b.intensity, clip.value_at(a.t_ms)[0]) == pytest.approx(max(a.intensity, clip.value_at(a.t_ms)[0]))
        assert b.balance == pytest.approx(a.balance, abs=1e-5)


def test_a_design_too_long_for_the_format_is_refused():
    with pytest.raises(ClipError, match="at most 600 s"):
        meta_haptic_data(HapticDesign((Segment(0.0, 700.0, 0.1, 0.1, 0.5, 0.5),), (), 700.0))
