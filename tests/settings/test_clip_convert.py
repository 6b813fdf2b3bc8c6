"""The knob mapping of imports and exports, and the round trips AHAP -> clip -> AHAP and clip -> AHAP -> clip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.formats.haptic_samples import ahap, curve, event, meta
from vibsynth.errors import ClipError
from vibsynth.formats.ahap import ahap_text, parse_ahap
from vibsynth.formats.haptic_design import HapticDesign, Segment, Tap
from vibsynth.formats.meta_haptic import parse_meta_haptic
from vibsynth.settings.clip_convert import ClipMapping, clip_from_design, clip_name, design_from_clip
from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir
from vibsynth.settings.config import load_config

DEFAULT = ClipMapping()
BENT = ClipMapping(intensity_exponent=2.0, balance_points=(-2.0, 0.5, 3.0), transient_decay_ms=25.0)


def test_mapping_defaults_follow_the_config_and_invert():
    config = load_config(env={}, user_file=False)
    m = ClipMapping.from_settings(config.settings)
    assert m == ClipMapping(1.0, (-3.5, 0.0, 3.5), 40.0)
    assert (m.balance(0.0), m.balance(0.5), m.balance(1.0), m.balance(0.75)) == (-3.5, 0.0, 3.5, 1.75)
    custom = load_config(
        env={},
        user_file=False,
        overrides={"clips.sharpness_0_balance": -1, "clips.intensity_exponent": 2, "knobs.balance_max": 2},
    )
    m2 = ClipMapping.from_settings(custom.settings)
    assert m2.balance_points == (-1.0, 0.0, 2.0) and m2.intensity(0.5) == 0.25
    rng = np.random.default_rng(3)
    for x in rng.uniform(0, 1, 50):
        assert BENT.sharpness(BENT.balance(x)) == pytest.approx(x)
        assert BENT.design_intensity(BENT.intensity(x)) == pytest.approx(x)
    assert BENT.sharpness(-9) == 0.0 and BENT.sharpness(9) == 1.0  # beyond the mapped range: clamped


def test_config_refuses_a_mapping_that_does_not_increase():
    from vibsynth.errors import ConfigError

    with pytest.raises(
        ConfigError, match=r"clips.sharpness_1_balance = -1 must be above clips.sharpness_half_balance = 0"
    ):
        load_config(env={}, user_file=False, overrides={"clips.sharpness_1_balance": -1})
    config = load_config(env={}, user_file=False, overrides={"clips.sharpness_half_balance": 5})
    with pytest.raises(ClipError, match=r"balances -3.5 < 5 < 3.5 at sharpness 0, 0.5, 1 must increase"):
        ClipMapping.from_settings(config.settings)


def test_clip_names_from_file_names():
    assert clip_name("Boing 2!") == "Boing-2" and clip_name("..") == "imported" and clip_name("a.b_c") == "a.b_c"


def test_steps_become_a_short_hold_and_constants_a_hold():
    design = HapticDesign(
        (Segment(0.0, 0.1, 0.2, 0.8, 0.5, 0.5), Segment(0.1, 0.3, 0.3, 0.3, 1.0, 1.0)), (Tap(0.05, 1.0, 0.0),), 0.3
    )
    clip = clip_from_design(design, "x", DEFAULT)
    assert [(k.t_ms, k.intensity, k.balance, k.interp) for k in clip.keyframes] == [
        (0.0, 0.2, 0.0, "linear"),
        (pytest.approx(99.999), 0.8, 0.0, "hold"),
        (100.0, 0.3, 3.5, "hold"),
    ]
    assert clip.transients[0].t_ms == 50.0 and clip.transients[0].balance == -3.5 and clip.transients[0].decay_ms == 40
    assert clip.value_at(50) == pytest.approx((0.5, 0.0), abs=1e-4) and clip.value_at(200) == (0.3, 3.5)


def test_an_exponent_is_followed_within_tolerance():
    design = HapticDesign((Segment(0.0, 1.0, 0.0, 1.0, 0.0, 1.0),), (), 1.0)
    clip = clip_from_design(design, "x", BENT)
    for t in np.linspace(0, 1, 101):
        i, b = clip.value_at(1000 * t)
        assert i**0.5 == pytest.approx(t, abs=0.0025) and b == pytest.approx(BENT.balance(t), abs=1e-5)


def test_a_design_too_dense_for_a_clip_is_one_clear_error():
    segs = tuple(Segment(k / 1e4, (k + 1) / 1e4, (k % 2) * 0.5, ((k + 1) % 2) * 0.5, 0.5, 0.5) for k in range(5000))
    with pytest.raises(ClipError, match=r"the design needs [\d,]+ keyframes .* a clip holds at most 4,096"):
        clip_from_design(HapticDesign(segs, (), 0.5), "x", DEFAULT)


# --------------------------------------------------------------------------- round trips
def _events(text: str) -> list[tuple[str, float, float, float, float]]:
    out = []
    for entry in json.loads(text)["Pattern"]:
        if "Event" in entry:
            e = entry["Event"]
            p = {q["ParameterID"]: q["ParameterValue"] for q in e["EventParameters"]}
            out.append(
                (e["EventType"], e["Time"], e.get("EventDuration", 0.0), p["HapticIntensity"], p["HapticSharpness"])
            )
    return sorted(out, key=lambda e: (e[1], e[0]))


@pytest.mark.parametrize("mapping", [DEFAULT, BENT], ids=["default", "bent"])
def test_ahap_clip_ahap_keeps_events_within_1ms_and_001(mapping):
    rng = np.random.default_rng(16)
    pattern, t = [], 0.0
    for _ in range(12):
        t += float(rng.uniform(0.01, 0.2))
        duration = float(rng.uniform(0.02, 0.3))
        i, s = (round(float(v), 3) for v in rng.uniform(0.05, 1, 2))
        pattern.append(event(round(t, 4), duration=round(duration, 4), intensity=i, sharpness=s))
        t += duration + float(rng.uniform(0.0, 0.05))
        if rng.random() < 0.7:
            i, s = (round(float(v), 3) for v in rng.uniform(0.05, 1, 2))
            pattern.append(event(round(t, 4), "HapticTransient", intensity=i, sharpness=s))
    original = ahap(*pattern)
    clip = clip_from_design(parse_ahap(original, "in.ahap"), "trip", mapping)
    exported = ahap_text(design_from_clip(clip, mapping))
    before, after = _events(original), _events(exported)
    assert len(before) == len(after) == len(pattern)
    for a, b in zip(before, after):
        assert a[0] == b[0]
        assert abs(a[1] - b[1]) <= 0.001 and abs(a[2] - b[2]) <= 0.001, (a, b)  # times within 1 ms
        assert abs(a[3] - b[3]) <= 0.01 and abs(a[4] - b[4]) <= 0.01, (a, b)  # values within 0.01


def test_ahap_with_curves_round_trips_what_is_felt():
    original = ahap(
        event(0.0, "HapticTransient", intensity=0.8, sharpness=0.4),
        event(0.015, duration=0.25, intensity=0.8, sharpness=0.4),
        curve("HapticIntensityControl", 0.015, [(0, 1), (0.1, 0.5), (0.25, 0)]),
        curve("HapticSharpnessControl", 0.015, [(0, 0), (0.25, -0.3)]),
        event(0.12, "HapticTransient", intensity=1.0, sharpness=0.9),
    )
    first = parse_ahap(original, "in.ahap")
    clip = clip_from_design(first, "boing", BENT)
    second = parse_ahap(ahap_text(design_from_clip(clip, BENT)), "out.ahap")
    for t in np.linspace(0, first.duration_s, 531):
        a, b = first.value_at(float(t)), second.value_at(float(t))
        assert abs(a[0] - b[0]) <= 0.01 and (a[0] < 0.01 or abs(a[1] - b[1]) <= 0.01), (t, a, b)
    # the transient at 0.12 s is scaled by the curves in force (as Core Haptics plays it), and kept
    assert first.taps[1].intensity == pytest.approx(0.5 - 0.5 * 0.005 / 0.15)
    assert first.taps[1].sharpness == pytest.approx(0.9 - 0.3 * 0.105 / 0.25)
    for x, y in zip(first.taps, second.taps, strict=True):
        assert (
            abs(x.t - y.t) <= 0.001
            and abs(x.intensity - y.intensity) <= 0.01
            and abs(x.sharpness - y.sharpness) <= 0.01
        )


def test_meta_haptic_import_maps_amplitude_frequency_and_emphasis():
    text = meta(
        [
            {"time": 0.0, "amplitude": 0.0},
            {"time": 0.05, "amplitude": 1.0, "emphasis": {"amplitude": 1.0, "frequency": 1.0}},
            {"time": 0.5, "amplitude": 0.0},
        ],
        [{"time": 0.0, "frequency": 0.25}, {"time": 0.5, "frequency": 0.75}],
    )
    clip = clip_from_design(parse_meta_haptic(text, "hit.haptic"), "hit", DEFAULT)
    assert clip.duration_ms == 500 and clip.transients[0].t_ms == 50
    assert (clip.transients[0].intensity, clip.transients[0].balance) == (1.0, 3.5)
    i, b = clip.value_at(25)
    assert i == pytest.approx(0.5) and b == pytest.approx(DEFAULT.balance(0.25 + 0.5 * 25 / 500))
    i, b = clip.value_at(400)
    assert i == pytest.approx(1 - 350 / 450) and b == pytest.approx(DEFAULT.balance(0.25 + 0.5 * 400 / 500))


@pytest.mark.parametrize("name", ["impact", "gravel-steps", "heartbeat", "zipper", "rain"])
def test_shipped_clips_survive_clip_ahap_clip(name):
    clip = ClipLibrary(shipped_clips_dir(), None).get(name)
    back = clip_from_design(parse_ahap(ahap_text(design_from_clip(clip, DEFAULT)), "x.ahap"), name, DEFAULT)
    times = np.linspace(0, clip.duration_ms, 2001)
    a, b = clip.values_at(times), back.values_at(times)
    felt = a[:, 0] > 0.01  # the balance of silence is not felt (and not kept)
    assert np.abs(a[:, 0] - b[:, 0]).max() <= 0.005 and np.abs(a[felt, 1] - b[felt, 1]).max() <= 0.01
    assert [v for t in back.transients for v in (t.t_ms, t.intensity, t.balance)] == pytest.approx(
        [v for t in clip.transients for v in (t.t_ms, t.intensity, t.balance)], abs=1e-3
    )
