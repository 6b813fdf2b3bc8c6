"""``vibsynth clip list|show|validate|import|export``: content of every output, and failures that change nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.formats.haptic_samples import ahap, curve, event, meta
from vibsynth.cli import main
from vibsynth.formats.ahap import read_ahap
from vibsynth.formats.meta_haptic import read_meta_haptic
from vibsynth.settings.clips import load_clip, shipped_clips_dir
from vibsynth.settings.config import ENV_VARS

BOING = ahap(
    event(0.0, "HapticTransient", intensity=0.8, sharpness=0.4),
    event(0.015, duration=0.25, intensity=0.8, sharpness=0.75),
    curve("HapticIntensityControl", 0.015, [(0, 1), (0.25, 0.0)]),
    event(0.3, "AudioCustom", EventWaveformPath="boing.wav"),
    Metadata={"Description": "a spring"},
)


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.chdir(tmp_path)
    return tmp_path / "data" / "vibsynth" / "clips"


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_list_table_csv_and_json(capsys):
    code, out, _ = run(capsys, "clip", "list")
    lines = out.splitlines()
    assert code == 0 and lines[0].split() == ["name", "ms", "keyframes", "transients", "loop", "from", "tags"]
    heart = next(line for line in lines if line.startswith("heartbeat"))
    assert heart.split()[:6] == ["heartbeat", "1000", "7", "2", "0-1000", "shipped"]
    assert "impact" in out and "5 clips; user folder:" in out
    code, out, _ = run(capsys, "clip", "list", "--json", "--tag", "loop")
    data = json.loads(out)
    assert sorted(d["name"] for d in data) == ["gravel-steps", "heartbeat", "rain", "zipper"]
    assert data[0]["keyframes"][0].keys() >= {"t_ms", "intensity", "balance"} and data[0]["origin"] == "shipped"
    code, out, _ = run(capsys, "clip", "list", "--format", "csv")
    assert out.splitlines()[0] == "name,duration_ms,keyframes,transients,loop,origin,tags"
    assert "zipper,720.0,6,19,100-600,shipped,zipper;mechanical;loop" in out


def test_show_prints_the_yaml_and_where_it_is(capsys):
    code, out, _ = run(capsys, "clip", "show", "impact")
    assert code == 0 and out.startswith("# shipped clip: ") and "(320 ms, 3 keyframes, 1 transients)" in out
    assert "name: impact" in out and "- {t_ms: 0, intensity: 1, balance: 2.2, decay_ms: 45}" in out
    code, out, _ = run(capsys, "clip", "show", "impact", "--json")
    assert json.loads(out)["duration_ms"] == 320
    code, _, err = run(capsys, "clip", "show", "impakt")
    assert code == 2 and "unknown clip 'impakt'; did you mean impact?" in err


def test_validate_names_the_line(tmp_path, capsys):
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text("duration_ms: 100\nkeyframes: [{t_ms: 0, intensity: 0.5, balance: 0}]\n")
    bad.write_text(
        "duration_ms: 100\nkeyframes:\n"
        "  - {t_ms: 0, intensity: 0.5, balance: 0}\n"
        "  - {t_ms: 0, intensity: 1, balance: 0}\n"
    )
    code, out, err = run(capsys, "clip", "validate", str(good), str(bad))
    assert code == 1 and f"{good}: OK (good: 100 ms, 1 keyframes, 0 transients)" in out
    assert f"{bad}:4: keyframes[1].t_ms = 0: keyframe times must strictly increase" in err
    assert "1 of 2 clip files are invalid" in err


def test_import_ahap_into_the_user_folder_then_export_it_back(tmp_path, capsys, isolated):
    src = tmp_path / "Boing Spring.ahap"
    src.write_text(BOING)
    code, out, err = run(capsys, "clip", "import", str(src))
    assert code == 0 and out.startswith(f"wrote {isolated / 'Boing-Spring.yaml'}: 265 ms")
    assert "vibsynth: warning:" in err and "AudioCustom events (audio is not played)" in err
    clip = load_clip(isolated / "Boing-Spring.yaml")
    assert clip.description == "a spring" and clip.transients[0].balance == pytest.approx(-0.7)
    assert clip.value_at(15) == pytest.approx((0.8, 1.75))  # sharpness 0.75 -> balance 1.75 (default mapping)
    code, out, _ = run(capsys, "clip", "list")
    assert "Boing-Spring" in out and "user" in out

    code, out, err = run(capsys, "clip", "export", "Boing-Spring", "--format", "ahap")
    assert code == 0 and out.startswith("wrote Boing-Spring.ahap") and "decay_ms is not exported" in err
    design = read_ahap(tmp_path / "Boing-Spring.ahap")
    assert design.taps[0].intensity == pytest.approx(0.8) and design.value_at(0.14)[0] == pytest.approx(0.4, abs=0.01)
    code, _, err = run(capsys, "clip", "export", "Boing-Spring")
    assert code == 1 and "exists already (use --force" in err
    code, out, _ = run(capsys, "clip", "export", "heartbeat", "-o", "-")
    assert json.loads(out)["Pattern"][0]["Event"]["EventType"] in ("HapticContinuous", "HapticTransient")


def test_import_with_name_output_and_mapping_from_the_config(tmp_path, capsys):
    src = tmp_path / "hit.haptic"
    src.write_text(
        meta([{"time": 0, "amplitude": 0.5}, {"time": 0.2, "amplitude": 0.5}], [{"time": 0, "frequency": 1.0}])
    )
    code, out, _ = run(
        capsys,
        "clip",
        "import",
        str(src),
        "--name",
        "hit2",
        "-o",
        str(tmp_path),
        "--set",
        "clips.sharpness_1_balance=1.5",
        "--set",
        "clips.intensity_exponent=2",
    )
    assert code == 0 and out.startswith(f"wrote {tmp_path / 'hit2.yaml'}")
    clip = load_clip(tmp_path / "hit2.yaml")
    assert clip.value_at(100) == pytest.approx((0.25, 1.5))


def test_a_failed_import_writes_nothing(tmp_path, capsys, isolated):
    bad = tmp_path / "nan.ahap"
    bad.write_text('{"Pattern": [{"Event": {"Time": NaN, "EventType": "HapticTransient"}}]}')
    code, _, err = run(capsys, "clip", "import", str(bad))
    assert code == 1 and err.startswith(f"vibsynth: error: {bad}: NaN is not a number") and err.count("\n") == 1
    assert not isolated.exists() or not any(isolated.iterdir())
    (tmp_path / "keep.ahap").write_text(BOING)
    assert run(capsys, "clip", "import", str(tmp_path / "keep.ahap"))[0] == 0
    before = (isolated / "keep.yaml").read_bytes()
    code, _, err = run(capsys, "clip", "import", str(tmp_path / "keep.ahap"))
    assert code == 1 and "exists already" in err and (isolated / "keep.yaml").read_bytes() == before


def test_schema_is_the_clip_schema(capsys):
    code, out, _ = run(capsys, "clip", "schema")
    schema = json.loads(out)
    assert code == 0 and schema["title"] == "vibsynth haptic clip" and "keyframes" in schema["required"]


def test_export_meta_haptic_and_import_it_back(tmp_path, capsys, isolated):
    code, out, err = run(capsys, "clip", "export", "impact", "--format", "haptic")
    assert code == 0 and out.startswith("wrote impact.haptic: 320 ms") and "as Meta .haptic" in out
    assert "Meta .haptic transients have a fixed shape" in err
    design = read_meta_haptic(tmp_path / "impact.haptic")
    assert design.taps[0].t == 0.0 and design.taps[0].intensity == pytest.approx(1.0)
    code, out, _ = run(capsys, "clip", "import", str(tmp_path / "impact.haptic"), "--name", "impact2")
    assert code == 0
    back, clip = load_clip(isolated / "impact2.yaml"), load_clip(shipped_clips_dir() / "impact.yaml")
    for t in range(0, 320, 7):
        assert back.value_at(t) == pytest.approx(clip.value_at(t), abs=0.005)
    code, out, _ = run(capsys, "clip", "export", "impact", "--format", "haptic", "-o", "-")
    assert json.loads(out)["signals"]["continuous"]["envelopes"]["amplitude"][0]["time"] == 0
    code, _, err = run(capsys, "clip", "export", "impact", "--format", "haptic")
    assert code == 1 and "exists already" in err
    blocked = tmp_path / "impact.haptic" / "x.haptic"  # its folder is a file
    code, _, err = run(capsys, "clip", "export", "impact", "--format", "haptic", "-o", str(blocked))
    assert code == 1 and err.startswith("vibsynth: error: ") and "cannot write" in err and err.count("\n") == 1


# --------------------------------------------------------------------------- from-audio
def _sound(path, seconds=1.5, seed=0, click=0.7, channels=1):
    from scipy.io import wavfile

    rng = np.random.default_rng(seed)
    x = rng.standard_normal(int(seconds * 48000)) * 0.005
    x[int(click * 48000)] += 0.9
    wavfile.write(path, 48000, np.tile(x[:, None], (1, channels)).astype(np.float32))
    return path


def test_from_audio_writes_a_named_clip_a_file_and_refuses_to_overwrite(tmp_path, capsys, isolated):
    src = _sound(tmp_path / "hit.wav", channels=2)
    code, out, err = run(capsys, "clip", "from-audio", str(src), "-o", "hit")
    assert code == 0 and out.startswith(f"wrote {isolated / 'hit.yaml'}: 1.50 s -> ") and "max error" in out
    clip = load_clip(isolated / "hit.yaml")
    assert clip.duration_ms == pytest.approx(1500) and "Followed from hit.wav (vibration mode)" in clip.description
    assert any(abs(t.t_ms - 700) < 10 for t in clip.transients)
    assert (isolated / "hit.yaml").read_text().startswith("# vibsynth clip made by clip from-audio from ")
    code, out, _ = run(capsys, "clip", "list")
    assert "hit" in out
    code, _, err = run(capsys, "clip", "from-audio", str(src), "-o", "hit")
    assert code == 1 and "exists already (use --force" in err and err.count("\n") == 1
    code, out, _ = run(
        capsys, "clip", "from-audio", str(src), "-o", str(tmp_path / "f.yaml"), "--mode", "audio", "--focus", "effects"
    )
    assert code == 0 and "audio mode, focus effects" in load_clip(tmp_path / "f.yaml").description
    code, out, _ = run(capsys, "clip", "from-audio", str(src), "-o", str(tmp_path / "g.yaml"), "--max-keyframes", "3")
    assert code == 0 and len(load_clip(tmp_path / "g.yaml").keyframes) <= 3 and "budget ran out" in out


def test_from_audio_takes_a_real_ogg_from_the_desktop_sound_theme(tmp_path, capsys, isolated):
    import shutil
    import subprocess
    from pathlib import Path

    oga = Path("/usr/share/sounds/freedesktop/stereo/complete.oga")
    if not oga.exists() or shutil.which("oggdec") is None:
        pytest.skip("sound-theme-freedesktop / vorbis-tools are not installed (scripts/setup.sh --test)")
    wav = tmp_path / "complete.wav"  # vorbis-tools' decode of the same file, for comparison
    subprocess.run(["oggdec", "-Q", "-o", str(wav), str(oga)], check=True, capture_output=True, timeout=60)
    code, out, err = run(capsys, "clip", "from-audio", str(oga), "-o", str(tmp_path / "o.yaml"), "--mode", "audio")
    assert code == 0 and err == "" and "1.09 s" in out
    code, _, _ = run(capsys, "clip", "from-audio", str(wav), "-o", str(tmp_path / "w.yaml"), "--mode", "audio")
    from_ogg, from_wav = load_clip(tmp_path / "o.yaml"), load_clip(tmp_path / "w.yaml")
    assert code == 0 and from_ogg.duration_ms == pytest.approx(from_wav.duration_ms)
    assert [round(t.t_ms) for t in from_ogg.transients] == [round(t.t_ms) for t in from_wav.transients]
    assert len(from_ogg.transients) >= 1  # the chime's strike


def test_from_audio_bad_files_write_nothing(tmp_path, capsys, isolated):
    from scipy.io import wavfile

    nan = np.zeros(4800, np.float32)
    nan[2400] = np.nan
    wavfile.write(tmp_path / "nan.wav", 48000, nan)
    (tmp_path / "trunc.wav").write_bytes((_sound(tmp_path / "t.wav")).read_bytes()[:1000])
    wavfile.write(tmp_path / "one.wav", 48000, np.zeros(1, np.int16))
    cases = {
        "nan.wav": "NaN or infinite sample at 0.050 s",
        "trunc.wav": "truncated or corrupt",
        "one.wav": "too short to follow",
        "missing.wav": "no such file or folder",
    }
    for name, message in cases.items():
        code, out, err = run(capsys, "clip", "from-audio", str(tmp_path / name), "-o", "x")
        assert code == 1 and message in err and err.startswith("vibsynth: error: ") and err.count("\n") == 1, err
    assert not isolated.exists() or not any(isolated.iterdir())
    with pytest.raises(SystemExit) as info:
        run(capsys, "clip", "from-audio", str(tmp_path / "t.wav"), "-o", "x", "--tolerance-db", "0")
    assert info.value.code == 2 and "outside (0, 40] dB" in capsys.readouterr().err


def test_from_audio_silence_says_so(tmp_path, capsys):
    from scipy.io import wavfile

    wavfile.write(tmp_path / "quiet.wav", 48000, np.zeros(48000, np.int16))
    code, out, _ = run(capsys, "clip", "from-audio", str(tmp_path / "quiet.wav"), "-o", str(tmp_path / "q.yaml"))
    assert code == 0 and "the input is silent: the clip is silence" in out
    assert all(k.intensity == 0 for k in load_clip(tmp_path / "q.yaml").keyframes)


def _folder(tmp_path):
    folder = tmp_path / "sounds"
    (folder / "sub").mkdir(parents=True)
    _sound(folder / "a.wav", seed=1)
    _sound(folder / "sub" / "B c.wav", seed=2, channels=2)
    (folder / "garbage.wav").write_bytes(b"RIFF....WAVEnope")
    (folder / "notes.txt").write_text("not a sound")
    return folder


def _check_folder_run(code, out, err, outdir):
    assert code == 1
    assert "vibsynth: error: " in err and "garbage.wav: not a readable WAV file" in err and err.count("\n") == 1
    assert "2 of 3 files converted (1 failed)" in out
    assert sorted(p.relative_to(outdir).as_posix() for p in outdir.rglob("*.yaml")) == ["a.yaml", "sub/B-c.yaml"]
    clip = load_clip(outdir / "sub" / "B-c.yaml")
    assert clip.name == "B-c" and any(abs(t.t_ms - 700) < 10 for t in clip.transients)


def test_a_folder_converts_in_parallel_and_reports_each_failure(tmp_path, capsys):
    folder = _folder(tmp_path)
    code, out, err = run(capsys, "clip", "from-audio", str(folder), "-o", str(tmp_path / "clips"), "--jobs", "2")
    _check_folder_run(code, out, err, tmp_path / "clips")
    assert "2 at a time" in out
    code, _, err = run(capsys, "clip", "from-audio", str(folder), "-o", str(tmp_path / "clips" / "a.yaml"))
    assert code == 2 and "needs an output folder" in err


def test_a_folder_converts_on_a_dask_cluster(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    folder = _folder(tmp_path)
    with distributed.LocalCluster(
        n_workers=2, processes=False, protocol="tcp", threads_per_worker=1, dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        code, out, err = run(capsys, "clip", "from-audio", str(folder), "-o", str(tmp_path / "c"), "--dask", address)
    _check_folder_run(code, out, err, tmp_path / "c")
    assert f"on {address}" in out


def test_import_to_a_file_takes_the_file_s_name(tmp_path, capsys):
    src = tmp_path / "hit.haptic"
    src.write_text(meta([{"time": 0, "amplitude": 0.5}, {"time": 0.2, "amplitude": 0.5}]))
    code, out, _ = run(capsys, "clip", "import", str(src), "-o", str(tmp_path / "back.yaml"))
    assert code == 0 and load_clip(tmp_path / "back.yaml").name == "back"


def test_a_folder_of_real_recordings_converts(tmp_path, capsys):
    """The spoken channel names of alsa-utils (recordings no one here made; scripts/setup.sh --test installs them)."""
    from pathlib import Path

    alsa = Path("/usr/share/sounds/alsa")
    if not any(alsa.glob("*.wav")):
        pytest.skip("alsa-utils' sounds are not installed")
    code, out, err = run(capsys, "clip", "from-audio", str(alsa), "-o", str(tmp_path / "alsa"), "--mode", "audio")
    sources = sorted(alsa.glob("*.wav"))
    assert code == 0 and err == "" and f"{len(sources)} of {len(sources)} files converted (0 failed)" in out
    for src in sources:
        clip = load_clip(tmp_path / "alsa" / f"{src.stem}.yaml")
        assert max(k.intensity for k in clip.keyframes) > 0.1  # a voice shakes (focus all)
