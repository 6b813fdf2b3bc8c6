"""``vibsynth preset ...``: list, show, new, from-recording (round trip through the engine), play -o."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibsynth.cli import main
from vibsynth.dsp.analysis import analyze
from vibsynth.dsp.intensity import knob_to_level_db
from vibsynth.dsp.synthesis import synthesize
from vibsynth.formats.recordings import read_recording, write_wav
from vibsynth.settings.config import ENV_VARS
from vibsynth.settings.presets import load_preset

FS = 8000.0
# A small, fast bank: 8 kHz, 2 s loops, 25 levels over [-2, 2]; no disk cache.
FAST = [
    "--set",
    "audio.rate=8000",
    "--set",
    "bank.loop_seconds=2",
    "--set",
    "bank.levels=25",
    "--set",
    "bank.balance_min=-2",
    "--set",
    "bank.balance_max=2",
    "--set",
    "knobs.balance_min=-2",
    "--set",
    "knobs.balance_max=2",
    "--set",
    "bank.cache_dir=''",
    "--set",
    "audio.block_size=256",
]


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("VIBSYNTH_PRESETS_DIR", str(tmp_path / "user-presets"))
    return tmp_path / "user-presets"


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_list_table_and_json(capsys):
    code, out, _ = run(capsys, "preset", "list")
    assert code == 0
    header = out.splitlines()[0].split()
    assert header == ["name", "intensity", "balance", "program", "from", "tags"]
    assert "towel" in out and "brick" in out
    code, out, _ = run(capsys, "preset", "list", "--json", "--sort", "balance")
    data = json.loads(out)
    assert len(data) >= 12 and {"name", "intensity", "balance", "program", "tags", "origin"} <= set(data[0])


def test_list_sorted_by_balance(capsys):
    _, out, _ = run(capsys, "preset", "list", "--sort", "balance")
    balances = [
        float(line.split()[2])
        for line in out.splitlines()[1:]
        if line and line[0] != "\n" and len(line.split()) > 4 and line.split()[2][0] in "+-"
    ]
    assert balances == sorted(balances) and len(balances) >= 12


def test_show_prints_yaml_and_file(capsys):
    code, out, _ = run(capsys, "preset", "show", "brick")
    assert code == 0 and out.startswith("# shipped preset: ") and "name: brick" in out and "provenance:" in out


def test_show_unknown_suggests(capsys):
    code, _, err = run(capsys, "preset", "show", "brik")
    assert code == 2 and "unknown preset 'brik'; did you mean brick" in err


def test_new_then_override_and_force(capsys, isolated):
    code, out, _ = run(
        capsys,
        "preset",
        "new",
        "mine",
        "--balance",
        "0.5",
        "--intensity",
        "0.25",
        "--tags",
        "soft,test",
        "--program",
        "100",
        "--glide-ms",
        "80",
    )
    assert code == 0 and (isolated / "mine.yaml").exists()
    p = load_preset(isolated / "mine.yaml")
    assert (p.balance, p.intensity, p.tags, p.program, p.glide_ms) == (0.5, 0.25, ("soft", "test"), 100, 80.0)
    code, _, err = run(capsys, "preset", "new", "mine", "--balance", "0", "--intensity", "0")
    assert code == 1 and "exists already (use --force" in err  # a file in the way: a runtime error
    code, _, err = run(capsys, "preset", "new", "brick", "--like", "brick", "--intensity", "0.1")
    assert code == 0 and "overrides the shipped preset" in err
    _, out, _ = run(capsys, "preset", "show", "brick")
    assert out.startswith("# user preset") and "intensity: 0.1" in out


@pytest.mark.parametrize(
    "args, message",
    [
        (["--balance", "5", "--intensity", "0.5"], "5 is outside the allowed range [-4, 4]"),
        (["--balance", "0", "--intensity", "1.5"], "1.5 is outside the allowed range [0, 1]"),
        (["--balance", "0", "--intensity", "nan"], "nan is outside the allowed range [0, 1]"),
        (["--balance", "0", "--intensity", "0.5", "--program", "200"], "200 is outside the allowed range [0, 127]"),
    ],
)
def test_new_rejects_out_of_range(capsys, args, message):
    with pytest.raises(SystemExit) as info:
        main(["preset", "new", "x", *args])
    assert info.value.code == 2 and message in capsys.readouterr().err


def test_new_needs_values(capsys):
    code, _, err = run(capsys, "preset", "new", "x")
    assert code == 2 and "give --intensity I and --balance B" in err


def test_new_bad_name(capsys):
    with pytest.raises(SystemExit) as info:  # refused by the argument parser, before anything is read
        main(["preset", "new", "a/b", "--balance", "0", "--intensity", "0.5"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "must be 1-64 letters" in err and err.count("\n") == 1


def _texture(basis, rng, *, balance: float, knob: float, seconds: float = 3.0) -> np.ndarray:
    """A recording-like texture: M + t1 V1 plus other components, at the level of an intensity knob."""
    scores = np.zeros(basis.n_components)
    scores[0] = float(basis.t1_from_balance(balance))
    scores[1:] = rng.normal(0, 3.0, basis.n_components - 1)
    level = knob_to_level_db(knob, ceiling_db=-40.0, range_db=40.0)
    return synthesize(basis.reconstruct(scores), fs=FS, n_samples=int(seconds * FS), level_db=level, rng=rng).signal


@pytest.mark.parametrize("balance, knob", [(-0.8, 0.7), (0.4, 0.5), (1.3, 0.85)])
def test_from_recording_round_trip_through_the_engine(capsys, tmp_path, isolated, basis, rng, balance, knob):
    recording = tmp_path / "rec.wav"
    write_wav(recording, _texture(basis, rng, balance=balance, knob=knob), FS)
    truth = analyze(read_recording(recording).samples, fs=FS, basis=basis, ceiling_db=-40.0, range_db=40.0)

    code, out, err = run(
        capsys,
        "preset",
        "from-recording",
        str(recording),
        "--name",
        "rec",
        "--set",
        "knobs.ceiling_db=-40",
        "--set",
        "knobs.range_db=40",
    )
    assert code == 0, err
    preset = load_preset(isolated / "rec.yaml")
    assert preset.balance == pytest.approx(truth.balance, abs=1e-3)
    assert preset.intensity == pytest.approx(truth.intensity_knob, abs=1e-3)
    prov = preset.provenance
    assert prov["recording"] == "rec.wav" and prov["basis_id"] == basis.id and prov["fs_hz"] == FS
    assert prov["t1"] == pytest.approx(truth.t1, abs=1e-3)

    rendered = tmp_path / "out.wav"
    code, out, err = run(
        capsys,
        "preset",
        "play",
        "rec",
        "--seconds",
        "3",
        "-o",
        str(rendered),
        "--set",
        "knobs.ceiling_db=-40",
        "--set",
        "knobs.range_db=40",
        *FAST,
    )
    assert code == 0, err
    samples = read_recording(rendered).samples[int(0.5 * FS) :]  # after the preset's glide
    again = analyze(samples, fs=FS, basis=basis, ceiling_db=-40.0, range_db=40.0)
    # The engine renders S1 (M + t1 V1) by interpolating a bank: balance within a small tolerance.
    assert again.balance == pytest.approx(truth.balance, abs=0.06)
    assert again.intensity_knob == pytest.approx(truth.intensity_knob, abs=0.5 / 40)  # 0.5 dB


def test_from_recording_exact_with_the_dsp_core(capsys, tmp_path, isolated, basis, rng):
    """Without the bank's interpolation the round trip is exact (synthesis imposes band powers exactly)."""
    recording = tmp_path / "r.wav"
    write_wav(recording, _texture(basis, rng, balance=-0.3, knob=0.6), FS)
    assert run(capsys, "preset", "from-recording", str(recording), "--set", "knobs.ceiling_db=-40")[0] == 0
    preset = load_preset(isolated / "r.yaml")
    level = knob_to_level_db(preset.intensity, ceiling_db=-40.0, range_db=40.0)
    x = synthesize(
        basis.spectrum_for_balance(preset.balance), fs=FS, n_samples=int(2 * FS), level_db=level, rng=rng
    ).signal
    again = analyze(x, fs=FS, basis=basis, ceiling_db=-40.0, range_db=40.0)
    assert again.balance == pytest.approx(preset.balance, abs=2e-3)
    assert again.intensity_knob == pytest.approx(preset.intensity, abs=1e-3)


def test_from_recording_clamps_loud_recordings_with_a_warning(capsys, tmp_path, isolated, basis, rng):
    recording = tmp_path / "loud.wav"
    x = _texture(basis, rng, balance=0.0, knob=1.0)
    write_wav(recording, x * 10 ** (20 / 20), FS)  # 20 dB above the ceiling
    code, _, err = run(capsys, "preset", "from-recording", str(recording), "--set", "knobs.ceiling_db=-40")
    assert code == 0 and "outside [0, 1]" in err and "clamped to 1" in err
    assert load_preset(isolated / "loud.yaml").intensity == 1.0


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "no such file"),
        (b"not a wav", "not a readable WAV file"),
    ],
)
def test_from_recording_bad_input(capsys, tmp_path, content, message):
    path = tmp_path / "bad.wav"
    if content is not None:
        path.write_bytes(content)
    code, _, err = run(capsys, "preset", "from-recording", str(path))
    assert code == 1 and message in err  # a bad file: a runtime error


def test_from_recording_silent(capsys, tmp_path):
    path = tmp_path / "silence.wav"
    write_wav(path, np.zeros(int(FS)), FS)
    code, _, err = run(capsys, "preset", "from-recording", str(path))
    assert code == 1 and "silence.wav" in err and "silent" in err


def test_play_to_wav_renders_the_preset(capsys, tmp_path, basis):
    out_wav = tmp_path / "brick.wav"
    code, out, err = run(capsys, "preset", "play", "brick", "--seconds", "2", "-o", str(out_wav), *FAST)
    assert code == 0, err
    x = read_recording(out_wav).samples
    assert x.size == int(2 * FS) and np.max(np.abs(x)) <= 0.891 + 1e-6
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    brick = PresetLibrary(shipped_presets_dir(), None).get("brick")
    result = analyze(x[int(0.5 * FS) :], fs=FS, basis=basis, ceiling_db=-40.0, range_db=40.0)
    assert result.balance == pytest.approx(brick.balance, abs=0.06)


def test_play_unknown_preset(capsys, tmp_path):
    code, _, err = run(capsys, "preset", "play", "nope", "-o", str(tmp_path / "x.wav"))
    assert code == 2 and "unknown preset 'nope'" in err
    assert not (tmp_path / "x.wav").exists()


def test_validate_names_every_bad_file_and_passes_good_ones(capsys, tmp_path):
    good, bad, yaml_error = tmp_path / "good.yaml", tmp_path / "bad.yaml", tmp_path / "typo.yaml"
    good.write_text("version: 1\nintensity: 0.5\nbalance: 0.2\n")
    bad.write_text("version: 1\nintensity: 0.5\nbalance: 9\n")
    yaml_error.write_text("version: 1\nintensity: 0.5\nbalance: [0.2\n")
    code, out, err = run(capsys, "preset", "validate", str(good))
    assert code == 0 and f"{good}: OK (good: intensity 0.500, balance +0.200)" in out
    code, out, err = run(capsys, "preset", "validate", str(good), str(bad), str(yaml_error))
    lines = err.splitlines()
    assert code == 1 and f"{good}: OK" in out
    assert lines[0].startswith(f"vibsynth: error: {bad}:3: balance = 9: outside the allowed range")
    assert lines[1].startswith(f"vibsynth: error: {yaml_error}:4") and "YAML syntax error" in lines[1]
    assert lines[2] == "2 of 3 preset files are invalid"


def test_a_broken_user_preset_says_what_is_wrong_everywhere(capsys, isolated, caplog):
    """Not "unknown preset": the file's own error, with file and line, for show and play alike."""
    isolated.mkdir(parents=True)
    (isolated / "mybrick.yaml").write_text("version: 1\nintensity: 0.5\nbalance: [0.2\n")
    for argv in (["preset", "show", "mybrick"], ["preset", "play", "mybrick", "-o", str(isolated / "x.wav")]):
        code, _, err = run(capsys, *argv)
        assert code == 1 and "unknown preset" not in err
        assert err.strip().splitlines()[-1].startswith(f"vibsynth: error: {isolated / 'mybrick.yaml'}:4")
    code, _, err = run(capsys, "preset", "show", "mybrik")
    assert code == 2 and "unknown preset 'mybrik'" in err


def test_rm_deletes_user_presets_only(capsys, isolated):
    assert run(capsys, "preset", "new", "mine", "--intensity", "0.4", "--balance", "0")[0] == 0
    code, out, _ = run(capsys, "preset", "rm", "mine")
    assert code == 0 and f"removed {isolated / 'mine.yaml'}" in out and not (isolated / "mine.yaml").exists()
    code, _, err = run(capsys, "preset", "rm", "brick")
    assert code == 2 and "shipped presets are read-only" in err
    assert run(capsys, "preset", "new", "brick", "--intensity", "0.4", "--balance", "0")[0] == 0  # an override
    code, out, _ = run(capsys, "preset", "rm", "brick")
    assert code == 0 and "the shipped preset of that name is used again" in out
    code, _, err = run(capsys, "preset", "rm", "nothing-like-it")
    assert code == 2 and "unknown preset" in err


def _calibrated_profile(folder, name="coil", rate=8000):
    """A measured profile as calibrate writes it (a 90 Hz resonance, the model curve's weighting and band)."""
    import yaml

    from vibsynth.app.calibrate import profile_band

    f = np.geomspace(5.0, 2000.0, 120)
    r = 8 * np.exp(-0.5 * (np.log2(f / 90) / 0.5) ** 2) - 10 * np.log10(1 + (20 / f) ** 4) - 4
    response = [[float(a), round(float(b), 3)] for a, b in zip(f, r, strict=True)]
    weighting, band = profile_band(response)
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"name": name, "absolute": True, "rate": rate, "response": response, "weighting": weighting, "band_hz": band}
    (folder / f"{name}.yaml").write_text(yaml.safe_dump(doc))
    return np.array(response)


def test_from_recording_with_a_calibrated_profile_renders_its_felt_intensity(capsys, tmp_path, isolated, basis, rng):
    """The preset's level is measured in the profile's weighting, the level the engine's knob then means."""
    from vibsynth.settings.actuators import profile_intensity

    points = _calibrated_profile(tmp_path / "cfg" / "vibsynth" / "actuators")
    weighting = profile_intensity("coil")
    recording = tmp_path / "felt.wav"
    write_wav(recording, _texture(basis, rng, balance=0.3, knob=0.6), FS)
    code, _, err = run(capsys, "preset", "from-recording", str(recording), "--name", "felt", "--profile", "coil")
    assert code == 0, err
    preset = load_preset(isolated / "felt.yaml")
    truth = analyze(read_recording(recording).samples, fs=FS, basis=basis, weighting=weighting)
    assert preset.intensity == pytest.approx(truth.intensity_knob, abs=1e-3)
    assert preset.provenance["intensity"] == weighting.describe() and "coil's weighting" in weighting.describe()
    paper = analyze(read_recording(recording).samples, fs=FS, basis=basis)
    assert abs(truth.level_db - paper.level_db) > 0.05  # the option changes what is measured (a little here)

    out = tmp_path / "drive.wav"
    code, _, err = run(
        capsys, "preset", "play", "felt", "--seconds", "4", "-o", str(out), *FAST,
        "--set", "actuator.profile=coil", "--set", "actuator.max_boost_db=40",
    )  # fmt: skip
    assert code == 0, err
    drive = read_recording(out).samples[int(2 * FS) :]  # one 2 s loop after the glide
    spectrum = np.fft.rfft(drive)
    freqs = np.fft.rfftfreq(drive.size, 1 / FS)
    gain = 10 ** (np.interp(np.log(np.maximum(freqs, 1.0)), np.log(points[:, 0]), points[:, 1]) / 20)
    felt = np.fft.irfft(spectrum * gain, n=drive.size)  # what the actuator does
    again = analyze(felt, fs=FS, basis=basis, weighting=weighting)
    assert again.intensity_knob == pytest.approx(truth.intensity_knob, abs=0.3 / 40)  # 0.3 dB
    assert again.balance == pytest.approx(truth.balance, abs=0.06)
