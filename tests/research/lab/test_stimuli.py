"""Stimulus sets: folders of WAVs (real HaTT texture spectra), presets, renders; preparation and versions."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from tests.research.lab.conftest import HATT_TEXTURES, RATE
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import write_wav
from vibsynth.research.lab.stimuli import (
    MAX_STIMULI,
    load_folder,
    load_renders,
    load_set,
    measure,
    parse_set_spec,
    prepare,
    reference_noise,
    resampled,
    resynthesis_versions,
    stimulus_id,
)


@pytest.mark.shared
def test_folder_of_wavs_gives_ids_and_the_middle_second(hatt_folder):
    s = load_folder(hatt_folder, seconds=1.0)
    assert s.kind == "folder" and not s.equalised
    assert sorted(s.ids) == sorted(stimulus_id(n) for n in HATT_TEXTURES)
    assert "Brick_1" in s.ids and "Aluminum_Foil" in s.ids
    brick = s.by_id()["Brick_1"]
    assert brick.fs == RATE and brick.samples.size == 2800
    from vibsynth.formats.recordings import read_recording

    whole = read_recording(hatt_folder / "Brick 1.wav").samples
    np.testing.assert_array_equal(brick.samples, whole[700:3500])  # the middle second of 1.5 s
    assert brick.params["file"].endswith("Brick 1.wav")


@pytest.mark.shared
def test_prepared_folder_keeps_the_textures_t1_and_sets_the_median_level(hatt_folder, basis):
    raw = load_folder(hatt_folder, seconds=1.0)
    t1_raw = {s.id: measure(s.samples, s.fs, basis)["t1"] for s in raw.stimuli}
    # real texture spectra differ: a bright cork against a dull brick
    assert t1_raw["Cork"] > 15 and t1_raw["Brick_1"] < -10
    for mode in ("std", "band", "none"):
        s = prepare(raw, mode=mode, level_db=-50.0, basis=basis)
        levels = np.array([x.params["level_db"] for x in s.stimuli])
        assert np.median(levels) == pytest.approx(-50.0, abs=1e-3)
        for x in s.stimuli:
            assert x.params["t1"] == pytest.approx(t1_raw[x.id], abs=1e-3)
            assert x.params["normalise"] == mode
            m = measure(x.samples, x.fs, basis)  # the params are what the samples measure
            assert m["level_db"] == pytest.approx(x.params["level_db"], abs=1e-3)
            assert m["rms"] == pytest.approx(x.params["rms"], rel=1e-6)
        if mode == "std":
            rms = [x.params["rms"] for x in s.stimuli]
            assert np.ptp(rms) < 1e-9 * max(rms)
            assert np.ptp(levels) > 5  # equal std leaves the band levels apart: the experiment's point
        if mode == "band":
            assert np.ptp(levels) < 1e-3
        if mode == "none":  # relative levels kept
            raw_levels = [measure(x.samples, x.fs, basis)["level_db"] for x in raw.stimuli]
            np.testing.assert_allclose(levels - levels[0], np.array(raw_levels) - raw_levels[0], atol=1e-3)


def test_folder_with_no_wavs_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("no stimuli here")
    (tmp_path / ".hidden.wav").write_bytes(b"RIFF")
    with pytest.raises(InputError, match="no WAV files"):
        load_folder(tmp_path, seconds=1.0)
    with pytest.raises(InputError, match="no such folder"):
        load_folder(tmp_path / "missing", seconds=1.0)
    with pytest.raises(InputError, match="is not a folder"):
        load_folder(tmp_path / "notes.txt", seconds=1.0)


def test_broken_wavs_are_named_and_refuse_the_set(tmp_path, rng):
    write_wav(tmp_path / "good.wav", rng.standard_normal(4000) * 0.1, 2800)
    (tmp_path / "text.wav").write_text("this is not audio")
    (tmp_path / "empty.wav").write_bytes(b"")
    write_wav(tmp_path / "short.wav", rng.standard_normal(1000) * 0.1, 2800)
    good = (tmp_path / "good.wav").read_bytes()
    (tmp_path / "cut.wav").write_bytes(good[:60])
    with pytest.raises(InputError) as err:
        load_folder(tmp_path, seconds=1.0)
    message = str(err.value)
    assert "4 WAV file(s) cannot be used" in message
    assert "cut.wav" in message and "empty.wav" in message and "(and 1 more)" in message
    assert "good.wav" not in message


def test_too_short_recordings_name_the_duration(tmp_path, rng):
    write_wav(tmp_path / "a.wav", rng.standard_normal(2000), 2800)
    with pytest.raises(InputError, match=r"a.wav: 0.71 s long; stimuli are 1 s"):
        load_folder(tmp_path, seconds=1.0)


def test_too_many_files_and_clashing_ids(tmp_path, rng):
    x = rng.standard_normal(3000) * 0.1
    write_wav(tmp_path / "a b.wav", x, 2800)
    write_wav(tmp_path / "a_b.wav", x, 2800)
    with pytest.raises(InputError, match="give the same stimulus id 'a_b'"):
        load_folder(tmp_path, seconds=1.0)
    many = tmp_path / "many"
    many.mkdir()
    for k in range(MAX_STIMULI + 1):
        (many / f"{k}.wav").write_bytes(b"")
    with pytest.raises(InputError, match=f"{MAX_STIMULI + 1} WAV files; a set has at most {MAX_STIMULI}"):
        load_folder(many, seconds=1.0)


def test_oversized_wav_is_refused_before_reading(tmp_path, monkeypatch, rng):
    import vibsynth.research.lab.stimuli as stimuli

    write_wav(tmp_path / "big.wav", rng.standard_normal(4000), 2800)
    monkeypatch.setattr(stimuli, "MAX_WAV_BYTES", 1000)
    with pytest.raises(InputError, match=r"big.wav: 16,\d+ bytes, over the 1000 bytes limit for a stimulus; not read"):
        load_folder(tmp_path, seconds=1.0)


def test_specs():
    assert parse_set_spec("presets").kind == "presets"
    assert parse_set_spec("presets: cork, wood").names == ("cork", "wood")
    assert parse_set_spec("renders:6").count == 6
    assert parse_set_spec("~/stimuli").folder == os.path.expanduser("~/stimuli") or True
    assert parse_set_spec("/data/x").text == "/data/x"
    for bad, message in [
        ("", "give 'presets'"),
        ("renders:1", "2..60"),
        ("renders:x", "2..60"),
        ("presets:,", "name at least"),
    ]:
        with pytest.raises(ParameterError, match=message):
            parse_set_spec(bad)


def test_presets_render_as_the_engine_plays_them(presets, basis):
    s = load_set("presets:cork,wood,brick", presets=presets, fs=8000, seconds=1.0, seed=3, basis=basis)
    assert s.ids == ["cork", "wood", "brick"]
    library = {p.name: p for p in presets()}
    from vibsynth.dsp.intensity import knob_to_level_db

    for st in s.stimuli:
        preset = library[st.id]
        m = measure(st.samples, st.fs, basis)
        assert m["level_db"] == pytest.approx(knob_to_level_db(preset.intensity), abs=0.05)
        assert float(basis.balance_from_t1(m["t1"])) == pytest.approx(preset.balance, abs=0.02)
    again = load_set("presets:cork,wood,brick", presets=presets, fs=8000, seconds=1.0, seed=3, basis=basis)
    np.testing.assert_array_equal(again.stimuli[0].samples, s.stimuli[0].samples)
    with pytest.raises(InputError, match="unknown preset.*nope"):
        load_set("presets:cork,nope", presets=presets, fs=8000, seconds=1.0, seed=3, basis=basis)
    all_presets = load_set("presets", presets=presets, fs=2800, seconds=0.5, seed=3, basis=basis)
    assert len(all_presets.stimuli) == 18


def test_renders_span_the_balance_at_one_level(basis):
    s = load_renders(6, fs=4000, seconds=1.0, seed=1, basis=basis)
    t1 = [measure(x.samples, x.fs, basis)["t1"] for x in s.stimuli]
    assert np.all(np.diff(t1) > 0)
    assert float(basis.balance_from_t1(t1[0])) == pytest.approx(-1.0, abs=0.02)
    assert float(basis.balance_from_t1(t1[-1])) == pytest.approx(1.0, abs=0.02)
    levels = [measure(x.samples, x.fs, basis)["level_db"] for x in s.stimuli]
    assert np.ptp(levels) < 0.05


@pytest.mark.shared
def test_reference_noise_sits_at_the_median_level_so_gains_fall_inside_the_range(hatt_folder, basis):
    s = prepare(load_folder(hatt_folder, seconds=1.0), mode="std", level_db=-50.0, basis=basis)
    ref = reference_noise(s.stimuli, seconds=1.0, seed=4, basis=basis)
    assert ref.id == "reference" and ref.fs == RATE and ref.samples.size == 2800
    assert ref.params["level_db"] == pytest.approx(-50.0, abs=1e-3)
    needed = [10 ** ((ref.params["level_db"] - x.params["level_db"]) / 20) for x in s.stimuli]
    assert all(0.2 <= g <= 5 for g in needed)
    # white: flat bands up to 1 kHz within the randomness of one second of noise
    bands = measure(ref.samples, ref.fs, basis)
    assert bands["t1"] != 0
    paper = reference_noise(s.stimuli, seconds=1.0, seed=4, basis=basis, match="std")
    assert paper.params["rms"] == pytest.approx(s.stimuli[0].params["rms"], rel=1e-6)


@pytest.mark.shared
def test_resynthesis_versions_keep_what_each_keeps(hatt_folder, basis):
    s = prepare(load_folder(hatt_folder, seconds=1.0), mode="band", level_db=-50.0, basis=basis)
    cork = s.by_id()["Cork"]
    versions = resynthesis_versions(cork, basis=basis, seed=1)
    assert list(versions) == ["O", "S1", "S1:8", "S2:8", "M"]
    assert versions["O"] is cork
    assert [v.id for v in list(versions.values())[1:]] == ["Cork.S1", "Cork.S1-8", "Cork.S2-8", "Cork.M"]
    t1 = cork.params["t1"]
    got = {k: v.params for k, v in versions.items()}
    assert got["S1"]["t1"] == pytest.approx(t1, abs=0.5)
    assert got["S1:8"]["t1"] == pytest.approx(t1, abs=0.5)
    np.testing.assert_allclose(got["S1:8"]["scores"], cork.params["scores"], atol=1.0)
    assert abs(got["S2:8"]["t1"]) < 1.0 and abs(got["M"]["t1"]) < 1.0
    for k in ("S1", "S1:8", "S2:8", "M"):
        assert got[k]["level_db"] == pytest.approx(cork.params["level_db"], abs=0.05)
        assert versions[k].samples.size == cork.samples.size
    again = resynthesis_versions(cork, basis=basis, seed=1)
    np.testing.assert_array_equal(again["S1"].samples, versions["S1"].samples)
    other = resynthesis_versions(cork, basis=basis, seed=2)
    assert not np.array_equal(other["S1"].samples, versions["S1"].samples)


def test_silent_stimulus_is_named(tmp_path, basis):
    write_wav(tmp_path / "quiet.wav", np.zeros(3000), 2800)
    raw = load_folder(tmp_path, seconds=1.0)
    with pytest.raises(InputError, match="stimulus quiet: signal is silent"):
        prepare(raw, mode="band", level_db=-50, basis=basis)


def test_resampling_keeps_the_band_level(rng, basis):
    x = rng.standard_normal(2800)
    y = resampled(x, 2800, 48000)
    assert y.size == 48000
    assert measure(y, 48000, basis)["level_db"] == pytest.approx(measure(x, 2800, basis)["level_db"], abs=0.1)
    assert resampled(x, 2800, 2800) is not None and math.isclose(
        resampled(x, 44100, 48000).size, 2800 * 48000 / 44100, abs_tol=1
    )
