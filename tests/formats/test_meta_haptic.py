"""Meta Haptics Studio ``.haptic`` (the Lofelt data model v1): envelopes, emphasis, steps, ignored keys, refusals."""

from __future__ import annotations

import json

import pytest

from tests.formats.haptic_samples import meta
from vibsynth.errors import ClipError
from vibsynth.formats.haptic_design import Tap
from vibsynth.formats.meta_haptic import MAX_HAPTIC_BYTES, parse_meta_haptic, read_meta_haptic

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
