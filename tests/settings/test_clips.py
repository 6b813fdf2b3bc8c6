"""Haptic clips: the schema and each of its errors (file:line), the curve, files, the library, hot reload."""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import pytest

from tests.settings.helpers import Recorder, edit
from vibsynth.errors import ClipError
from vibsynth.settings.clips import (
    MAX_CLIP_BYTES,
    Clip,
    ClipLibrary,
    ClipWatcher,
    InvalidClipError,
    Keyframe,
    Transient,
    UnknownClipError,
    clip_to_yaml,
    load_clip,
    load_clip_library,
    parse_clip,
    save_clip,
    shipped_clips_dir,
)
from vibsynth.settings.config import load_config
from vibsynth.settings.models_clip import MAX_KEYFRAMES, MAX_TRANSIENTS

GOOD = """\
description: a test clip
tags: [test]
duration_ms: 1000
loop: {start_ms: 100, end_ms: 900}
keyframes:
  - {t_ms: 0, intensity: 0.2, balance: -1}
  - {t_ms: 100, intensity: 0.8, balance: 1, interp: hold}
  - {t_ms: 500, intensity: 0.4, balance: 0, interp: smooth}
  - {t_ms: 900, intensity: 0.0, balance: 2}
transients:
  - {t_ms: 300, intensity: 0.9, balance: 2.5, decay_ms: 40}
  - {t_ms: 0, intensity: 1, balance: 0, decay_ms: 20}
"""


def parse(text: str) -> Clip:
    return parse_clip(text, "x.yaml", name="x")


def replaced(old: str, new: str) -> str:
    assert old in GOOD
    return GOOD.replace(old, new, 1)


# --------------------------------------------------------------------------- schema
def test_good_clip_parses_to_the_dataclasses():
    c = parse(GOOD)
    assert c.name == "x" and c.duration_ms == 1000.0 and c.loop == (100.0, 900.0) and c.tags == ("test",)
    assert c.description == "a test clip"
    assert c.keyframes[1] == Keyframe(100.0, 0.8, 1.0, "hold")
    assert [k.interp for k in c.keyframes] == ["linear", "hold", "smooth", "linear"]
    assert c.transients == (Transient(0.0, 1.0, 0.0, 20.0), Transient(300.0, 0.9, 2.5, 40.0))  # sorted by time


@pytest.mark.parametrize(
    "old, new, message, key",
    [
        (
            "{t_ms: 500,",
            "{t_ms: 50,",
            "x.yaml:8: keyframes[2].t_ms = 50: keyframe times must strictly increase (keyframes[1].t_ms = 100)",
            "keyframes[2].t_ms",
        ),
        (
            "{t_ms: 500,",
            "{t_ms: 100,",
            "x.yaml:8: keyframes[2].t_ms = 100: keyframe times must strictly increase",
            "keyframes[2].t_ms",
        ),
        (
            "{t_ms: 900, intensity: 0.0",
            "{t_ms: 1200, intensity: 0.0",
            "x.yaml:9: keyframes[3].t_ms = 1200: keyframe at 1200 ms is after the end of the clip (duration_ms = 1000)",
            "keyframes[3].t_ms",
        ),
        (
            "intensity: 0.8",
            "intensity: 1.5",
            "x.yaml:7: keyframes[1].intensity = 1.5: outside the allowed range [0, 1]",
            "keyframes[1].intensity",
        ),
        (
            "balance: 2}",
            "balance: 11}",
            "x.yaml:9: keyframes[3].balance = 11: outside the allowed range [-10, 10] (knob units)",
            "keyframes[3].balance",
        ),
        (
            "interp: hold",
            "interp: cubic",
            "x.yaml:7: keyframes[1].interp = 'cubic': not an allowed value (allowed: one of linear, hold, smooth)",
            "keyframes[1].interp",
        ),
        (
            "{t_ms: 500,",
            "{t_ms: .nan,",
            "x.yaml:8: keyframes[2].t_ms = nan: must be finite",
            "keyframes[2].t_ms",
        ),
        (
            "{t_ms: 500,",
            "{t_ms: '500',",
            "x.yaml:8: keyframes[2].t_ms = '500': must be a number",
            "keyframes[2].t_ms",
        ),
        (
            "{t_ms: 500,",
            "{t_ms: 500, speed: 2,",
            "x.yaml:8: unknown key 'keyframes[2].speed' (allowed: t_ms, intensity, balance, interp)",
            "keyframes[2].speed",
        ),
        (
            "decay_ms: 40",
            "decay_ms: 0",
            "x.yaml:11: transients[0].decay_ms = 0: outside the allowed range (0, 2000] ms",
            "transients[0].decay_ms",
        ),
        (
            "decay_ms: 40",
            "decay_ms: 2500",
            "x.yaml:11: transients[0].decay_ms = 2500: outside the allowed range (0, 2000] ms",
            "transients[0].decay_ms",
        ),
        (
            "{t_ms: 300,",
            "{t_ms: 1300,",
            "x.yaml:11: transients[0].t_ms = 1300: transient at 1300 ms is after the end of the clip",
            "transients[0].t_ms",
        ),
        (
            "end_ms: 900}",
            "end_ms: 1500}",
            "x.yaml:4: loop.end_ms = 1500: loop end 1500 ms is after the end of the clip (duration_ms = 1000)",
            "loop.end_ms",
        ),
        (
            "start_ms: 100,",
            "start_ms: 950,",
            "x.yaml:4: loop.end_ms = 900: must be after start_ms = 950 ms",
            "loop.end_ms",
        ),
        (
            "duration_ms: 1000",
            "duration_ms: 0",
            "x.yaml:3: duration_ms = 0: outside the allowed range (0, 600000] ms",
            "duration_ms",
        ),
        (
            "duration_ms: 1000",
            "duration_ms: 700000",
            "x.yaml:3: duration_ms = 700000: outside the allowed range (0, 600000] ms",
            "duration_ms",
        ),
        (
            "tags: [test]",
            "tags: test",
            "x.yaml:2: tags = 'test': must be a list, e.g. tags: [test]",
            "tags",
        ),
        (
            "tags: [test]",
            "tagz: [test]",
            "x.yaml:2: unknown key 'tagz'; did you mean 'tags'?",
            "tagz",
        ),
    ],
)
def test_each_error_names_file_line_key_value_and_range(old, new, message, key):
    with pytest.raises(InvalidClipError) as info:
        parse(replaced(old, new))
    assert str(info.value).startswith(message)
    assert info.value.problems[0].key == key
    assert isinstance(info.value, ClipError)


def test_all_problems_are_kept_in_file_order():
    text = replaced("intensity: 0.8", "intensity: 1.5").replace("decay_ms: 40", "decay_ms: -1")
    with pytest.raises(InvalidClipError) as info:
        parse(text)
    assert [(p.key, p.line) for p in info.value.problems] == [
        ("keyframes[1].intensity", 7),
        ("transients[0].decay_ms", 11),
    ]


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "x.yaml: the file is empty (a clip needs at least duration_ms and keyframes)"),
        ("- 1\n- 2\n", "x.yaml: a clip must be a mapping of keys"),
        ("duration_ms: 100\n", "x.yaml: missing key 'keyframes'"),
        ("duration_ms: 100\nkeyframes: []\n", "x.yaml:2: keyframes = []: has 0 items (allowed: at least 1)"),
        (
            "name: y\nduration_ms: 100\nkeyframes: [{t_ms: 0, intensity: 0, balance: 0}]\n",
            "x.yaml:1: name = 'y' does not match",
        ),
        ("duration_ms: 100\nduration_ms: 200\n", "x.yaml:2: key 'duration_ms' appears twice (first on line 1)"),
        ("a: &x [1]\nb: *x\n", "aliases are not allowed in a clip"),
        ("duration_ms: [\n", "x.yaml"),
    ],
)
def test_file_level_errors(text, message):
    with pytest.raises(ClipError) as info:
        parse(text)
    assert message in str(info.value)


def test_count_caps_refuse_too_many_keyframes_and_transients():
    many = "".join(f"  - {{t_ms: {i}, intensity: 0, balance: 0}}\n" for i in range(MAX_KEYFRAMES + 1))
    with pytest.raises(InvalidClipError, match=rf"keyframes = .*has {MAX_KEYFRAMES + 1} items \(allowed: at most"):
        parse(f"duration_ms: {MAX_KEYFRAMES + 1}\nkeyframes:\n{many}")
    bursts = "".join("  - {t_ms: 0, intensity: 1, balance: 0, decay_ms: 5}\n" for _ in range(MAX_TRANSIENTS + 1))
    with pytest.raises(InvalidClipError, match=rf"transients = .*has {MAX_TRANSIENTS + 1} items"):
        parse(f"duration_ms: 10\nkeyframes: [{{t_ms: 0, intensity: 0, balance: 0}}]\ntransients:\n{bursts}")


def test_oversized_file_is_refused_before_reading(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * MAX_CLIP_BYTES + "\n")
    with pytest.raises(ClipError, match=r"big.yaml: .* over the 1 MiB limit for a clip; not read"):
        load_clip(big)


# --------------------------------------------------------------------------- the curve
def test_value_at_implements_linear_hold_and_smooth():
    c = parse(GOOD)
    assert c.value_at(-5) == (0.2, -1.0)  # before the first keyframe: its value
    assert c.value_at(50) == pytest.approx((0.5, 0.0))  # linear half way
    assert c.value_at(100) == (0.8, 1.0)
    assert c.value_at(499.9) == (0.8, 1.0)  # hold until the next keyframe...
    assert c.value_at(500) == (0.4, 0.0)  # ...then step
    assert c.value_at(700) == pytest.approx((0.2, 1.0))  # smooth: the midpoint is the mean
    w = 0.5 - 0.5 * math.cos(math.pi * 0.25)  # a quarter of the way: cosine ease
    assert c.value_at(600) == pytest.approx((0.4 - 0.4 * w, 2 * w))
    assert c.value_at(900) == (0.0, 2.0) and c.value_at(5000) == (0.0, 2.0)  # after the last: held


def test_smooth_has_zero_slope_at_both_keyframes():
    c = parse(GOOD)
    eps = 1e-3
    start = (c.value_at(500 + eps)[0] - c.value_at(500)[0]) / eps
    end = (c.value_at(900)[0] - c.value_at(900 - eps)[0]) / eps
    middle = (c.value_at(700 + eps)[0] - c.value_at(700)[0]) / eps
    assert abs(start) < 1e-4 and abs(end) < 1e-4 and middle < -1e-3


def test_values_at_matches_value_at_everywhere():
    rng = np.random.default_rng(16)
    c = parse(GOOD)
    times = np.concatenate([rng.uniform(-100, 1100, 500), [k.t_ms for k in c.keyframes]])
    got = c.values_at(times)
    assert got.shape == (times.size, 2)
    np.testing.assert_allclose(got, [c.value_at(float(t)) for t in times], atol=1e-12)


def test_single_keyframe_clip_is_constant():
    c = parse_clip("duration_ms: 50\nkeyframes: [{t_ms: 10, intensity: 0.3, balance: 0.5}]\n", "c.yaml", name="c")
    assert c.value_at(0) == c.value_at(10) == c.value_at(49) == (0.3, 0.5)
    np.testing.assert_array_equal(c.values_at([0, 60]), [[0.3, 0.5], [0.3, 0.5]])


# --------------------------------------------------------------------------- files
def test_save_and_load_round_trip(tmp_path):
    c = parse(GOOD)
    path = save_clip(Clip(**{**c.__dict__, "name": "mine"}), tmp_path / "mine.yaml")
    back = load_clip(path, origin="user")
    assert back == Clip(**{**c.__dict__, "name": "mine"}) and back.path == path and back.origin == "user"
    text = path.read_text()
    assert "- {t_ms: 100, intensity: 0.8, balance: 1, interp: hold}" in text  # one keyframe per line, no 100.0
    assert "{t_ms: 0, intensity: 0.2, balance: -1}" in text  # linear is the default: left out


def test_save_refuses_a_clip_it_could_not_read_back(tmp_path):
    bad = Clip("bad", 100.0, (Keyframe(0, 2.0, 0),))
    with pytest.raises(InvalidClipError, match="intensity = 2"):
        save_clip(bad, tmp_path / "bad.yaml")
    assert not (tmp_path / "bad.yaml").exists()
    with pytest.raises(ClipError, match="no file to save to"):
        save_clip(Clip("x", 10.0, (Keyframe(0, 0, 0),)))


def test_shipped_clips_load_and_are_designed(tmp_path):
    lib = ClipLibrary(shipped_clips_dir(), None)
    assert lib.names() == ["gravel-steps", "heartbeat", "impact", "rain", "zipper"] and not lib.errors
    for clip in lib.clips():
        assert clip.description and clip.tags and clip.origin == "shipped"
        assert clip_to_yaml(clip).count("\n") > 8
    impact, heart, steps = lib.get("impact"), lib.get("heartbeat"), lib.get("gravel-steps")
    assert impact.loop is None and impact.transients[0].t_ms == 0 and impact.value_at(impact.duration_ms)[0] == 0
    assert heart.loop == (0.0, 1000.0) and [t.t_ms for t in heart.transients] == [0.0, 300.0]
    assert all(t.balance < 0 for t in heart.transients)  # a dull thump: darker than the mean spectrum
    for looped in (heart, steps, lib.get("rain"), lib.get("zipper")):
        start, end = looped.loop or (0.0, 0.0)
        assert end > start
        assert looped.value_at(start) == pytest.approx(looped.value_at(end))  # seamless loop
    assert len(lib.get("rain").transients) > 40 and len(steps.transients) >= 4


# --------------------------------------------------------------------------- the library
@pytest.fixture
def dirs(tmp_path):
    shipped, user = tmp_path / "shipped", tmp_path / "user"
    shipped.mkdir()
    for name, level in (("thud", 0.5), ("tick", 0.2)):
        (shipped / f"{name}.yaml").write_text(
            f"duration_ms: 100\nkeyframes: [{{t_ms: 0, intensity: {level}, balance: 0}}]\n"
        )
    return shipped, user


def one(level: float) -> str:
    return f"duration_ms: 100\nkeyframes: [{{t_ms: 0, intensity: {level}, balance: 0}}]\n"


def test_user_clip_overrides_shipped_and_unknown_names_get_close_ones(dirs):
    shipped, user = dirs
    user.mkdir()
    (user / "thud.yaml").write_text(one(0.9))
    lib = ClipLibrary(shipped, user)
    assert lib.names() == ["thud", "tick"]
    assert lib.get("thud").keyframes[0].intensity == 0.9 and lib.get("thud").origin == "user"
    with pytest.raises(UnknownClipError, match=r"unknown clip 'thd'; did you mean thud\? \(2 clips: 1 shipped, 1 in "):
        lib.get("thd")
    with pytest.raises(UnknownClipError, match=r"`vibsynth clip list` shows them"):
        lib.get("zzz")


def test_broken_file_is_skipped_with_one_warning_and_named_by_get(dirs, caplog):
    shipped, user = dirs
    user.mkdir()
    (user / "bad.yaml").write_text("duration_ms: 100\nkeyframes: [{t_ms: 0, intensity: 3, balance: 0}]\n")
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"):
        lib = ClipLibrary(shipped, user)
        lib.reload()
        lib.reload()
    warnings = [r.getMessage() for r in caplog.records if "bad.yaml" in r.getMessage()]
    assert len(warnings) == 1 and "bad.yaml:2: keyframes[0].intensity = 3" in warnings[0]
    assert lib.names() == ["thud", "tick"]
    with pytest.raises(ClipError, match=r"bad.yaml:2: keyframes\[0\].intensity = 3") as info:
        lib.get("bad")
    assert not isinstance(info.value, UnknownClipError)


def test_save_user_writes_and_reloads(dirs):
    shipped, user = dirs
    lib = ClipLibrary(shipped, user)
    clip = Clip("new-one", 200.0, (Keyframe(0, 0.1, 0.0), Keyframe(200, 0.5, 1.0, "smooth")))
    path = lib.save_user(clip)
    assert path == user / "new-one.yaml" and lib.get("new-one") == clip
    with pytest.raises(ClipError, match="exists already"):
        lib.save_user(clip)
    with pytest.raises(ClipError, match=r"clip name '\.\./x': must be 1-64 letters"):
        lib.user_path("../x")


def test_load_clip_library_uses_the_config_folder(tmp_path):
    config = load_config(env={}, user_file=False, overrides={"clips.user_dir": str(tmp_path / "mine")})
    lib = load_clip_library(config.settings)
    assert lib.user_dir == tmp_path / "mine" and lib.shipped_dir == shipped_clips_dir()
    assert "heartbeat" in lib


def test_default_user_folder_is_the_platform_data_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    lib = load_clip_library(load_config(env={}, user_file=False).settings)
    assert lib.user_dir == tmp_path / "data" / "vibsynth" / "clips"


def test_hot_reload_edit_break_fix_add_delete(dirs, caplog):
    shipped, user = dirs
    user.mkdir()
    target = user / "mine.yaml"
    target.write_text(one(0.3))
    lib = ClipLibrary(shipped, user)
    rec = Recorder()
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"), ClipWatcher(lib, rec, interval_s=0.05) as watcher:
        assert watcher._thread is not None and watcher._thread.name == "vibsynth-clip-watcher"
        edit(target, one(0.6))
        assert rec.wait(5.0) == ["mine"] and lib.get("mine").keyframes[0].intensity == 0.6
        edit(target, one(7))  # broken: the last good version stays
        deadline = time.monotonic() + 5
        while "intensity = 7" not in lib.errors.get(str(target), "") and time.monotonic() < deadline:
            time.sleep(0.01)
        assert "mine.yaml:2: keyframes[0].intensity = 7" in lib.errors[str(target)]
        assert lib.get("mine").keyframes[0].intensity == 0.6 and rec.calls == []
        edit(target, one(0.7))
        assert rec.wait(5.0) == ["mine"] and not lib.errors
        save_clip(Clip("extra", 10.0, (Keyframe(0, 0.2, 0.0),)), user / "extra.yaml")
        assert rec.wait(5.0) == ["extra"]
        target.unlink()
        assert rec.wait(5.0) == ["mine"] and lib.names() == ["extra", "thud", "tick"]
    assert "clip 'mine' changed" in caplog.text and "clip 'extra' added" in caplog.text


def test_watcher_interval_is_checked():
    with pytest.raises(ClipError, match=r"watch interval 0 s is outside the allowed range \(0, 10\] s"):
        ClipWatcher(ClipLibrary(None, None), lambda name: None, interval_s=0)


def test_a_folder_of_exactly_the_file_cap_is_not_reported(tmp_path, monkeypatch, caplog):
    import vibsynth.settings.library as vl

    monkeypatch.setattr(vl, "MAX_FILES_PER_FOLDER", 3)
    for i in range(3):
        (tmp_path / f"c{i}.yaml").write_text(one(0.1 * i))
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"):
        lib = ClipLibrary(None, tmp_path)
        assert len(lib) == 3 and "clip files" not in caplog.text
        (tmp_path / "c3.yaml").write_text(one(0.5))
        lib.reload()
        lib.reload()
    assert len(lib) == 3
    assert [r.getMessage() for r in caplog.records] == [
        f"clip folder {tmp_path}: more than 3 clip files; only 3 are used"
    ]
