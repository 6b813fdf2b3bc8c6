"""``vibsynth render --follow`` (a file, a folder) and ``render --clip FILE.yaml``: what is written, failures."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.io import wavfile

from tests.cli.test_clip_cli import isolated  # noqa: F401 (the same isolated HOME, config and folders)
from vibsynth.cli import main
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.formats.recordings import read_recording
from vibsynth.settings.clips import load_clip, save_clip, shipped_clips_dir

FS = 48000


def _steps(path, seed=0):
    x = np.random.default_rng(seed).standard_normal(2 * FS) * 0.02
    x[FS:] *= 0.1  # -20 dB at 1 s
    wavfile.write(path, FS, x.astype(np.float32))
    return x


def test_render_follow_writes_the_haptic_track_aligned_and_as_long_as_the_input(tmp_path, capsys):
    x = _steps(tmp_path / "in.wav")
    assert main(["render", "--follow", "in.wav", "-o", "out.wav"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("wrote out.wav: 2.00 s at 48000 Hz, peak ")
    rec = read_recording(tmp_path / "out.wav")
    y = rec.samples
    assert rec.fs == FS and y.size == x.size
    for a, b in ((0.2, 0.9), (1.1, 1.9)):
        s = slice(int(a * FS), int(b * FS))
        assert intensity_level_db(y[s], fs=FS) == pytest.approx(intensity_level_db(x[s], fs=FS), abs=1.5)
    # the step is where the input's is: 10 ms each side of it differ by most of the 20 dB
    before = intensity_level_db(y[int(0.95 * FS) : int(0.99 * FS)], fs=FS)
    after = intensity_level_db(y[int(1.01 * FS) : int(1.05 * FS)], fs=FS)
    assert before - after > 12


def test_render_follow_at_another_rate_and_in_audio_mode(tmp_path, capsys):
    _steps(tmp_path / "in.wav")
    cfg = tmp_path / "small.yaml"
    cfg.write_text("bank:\n  levels: 9\n  loop_seconds: 1.0\n")
    args = ["render", "--follow", "in.wav", "--rate", "8000", "--config", str(cfg), "-q", "-o", "o.wav"]
    assert main([*args, "--follow-mode", "audio", "--follow-focus", "all"]) == 0
    rec = read_recording(tmp_path / "o.wav")
    assert rec.fs == 8000 and rec.samples.size == 16000 and capsys.readouterr().out == ""
    assert np.sqrt(np.mean(rec.samples[:7000] ** 2)) > 3 * np.sqrt(np.mean(rec.samples[9000:] ** 2))


def test_render_follow_a_folder_and_bad_files(tmp_path, capsys):
    (tmp_path / "snd").mkdir()
    _steps(tmp_path / "snd" / "a.wav", seed=1)
    _steps(tmp_path / "snd" / "b.wav", seed=2)
    (tmp_path / "snd" / "c.wav").write_bytes(b"RIFF\xff\xff\xff\xffWAVEfmt ")
    code = main(["render", "--follow", "snd", "-o", "tracks", "--jobs", "2"])
    out, err = capsys.readouterr()
    assert code == 1 and "2 of 3 files converted (1 failed)" in out and err.count("\n") == 1 and "c.wav" in err
    assert sorted(p.name for p in (tmp_path / "tracks").iterdir()) == ["a.wav", "b.wav"]
    assert read_recording(tmp_path / "tracks" / "b.wav").samples.size == 2 * FS


def test_render_follow_takes_flac_and_ogg_like_the_same_wav(tmp_path, capsys):
    import soundfile

    (tmp_path / "snd").mkdir()
    x = _steps(tmp_path / "snd" / "a.wav", seed=3)
    soundfile.write(tmp_path / "snd" / "b.flac", x, FS, subtype="PCM_24")  # lossless: the same track
    soundfile.write(tmp_path / "snd" / "c.ogg", x, FS, format="OGG", subtype="VORBIS")
    (tmp_path / "snd" / "notes.txt").write_text("not a sound")  # not a sound file's name: not picked
    code = main(["render", "--follow", "snd", "-o", "tracks", "--jobs", "1"])
    out, err = capsys.readouterr()
    assert code == 0 and err == "" and "3 of 3 files converted" in out
    a, b, c = (read_recording(tmp_path / "tracks" / f"{n}.wav").samples for n in "abc")
    assert b.size == c.size == a.size == x.size
    assert np.max(np.abs(a - b)) < 1e-4  # 24-bit rounding of the input is all that differs
    for lo, hi in ((0.2, 0.9), (1.1, 1.9)):  # Vorbis changes the noise's fine detail, not its level
        s = slice(int(lo * FS), int(hi * FS))
        assert intensity_level_db(c[s], fs=FS) == pytest.approx(intensity_level_db(a[s], fs=FS), abs=0.5)


def test_render_follow_failures_are_one_line_and_write_nothing(tmp_path, capsys):
    x = np.zeros(FS, np.float32)
    x[100] = np.inf
    wavfile.write(tmp_path / "inf.wav", FS, x)
    assert main(["render", "--follow", "inf.wav", "-o", "o.wav"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("vibsynth: error: inf.wav: NaN or infinite sample at 0.002 s") and err.count("\n") == 1
    assert not (tmp_path / "o.wav").exists() and not list(tmp_path.glob(".o.wav*"))
    assert main(["render", "--balance", "0", "--intensity", "0.5", "--follow-mode", "audio", "-o", "o.wav"]) == 2
    assert "--follow-mode, --follow-focus, --jobs and --dask go with --follow" in capsys.readouterr().err
    assert main(["render", "--follow", "inf.wav", "--seconds", "2", "-o", "o.wav"]) == 2
    assert "--seconds does not apply" in capsys.readouterr().err


def test_render_clip_takes_a_clip_file(tmp_path, capsys):
    clip = load_clip(shipped_clips_dir() / "impact.yaml")
    save_clip(replace(clip, name="mine"), tmp_path / "mine.yaml")
    cfg = tmp_path / "small.yaml"
    cfg.write_text("bank:\n  levels: 9\n  loop_seconds: 1.0\n")
    common = ["--rate", "8000", "--config", str(cfg), "-q"]
    assert main(["render", "--clip", str(tmp_path / "mine.yaml"), *common, "-o", "a.wav"]) == 0
    assert main(["render", "--clip", "impact", *common, "-o", "b.wav"]) == 0
    a, b = read_recording(tmp_path / "a.wav").samples, read_recording(tmp_path / "b.wav").samples
    assert a.size == b.size and np.max(np.abs(a)) > 0  # the same clip, from its file or by name
    assert main(["render", "--clip", "./nope.yaml", *common, "-o", "c.wav"]) == 1
    assert "nope.yaml: no such file" in capsys.readouterr().err
