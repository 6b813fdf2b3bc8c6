"""CLI: compare, dissim fit, encode/decode (run in-process through vibsynth.cli.main)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibsynth.cli import main
from vibsynth.dsp.synthesis import synthesize
from vibsynth.formats.recordings import write_wav

FS = 2800.0


@pytest.fixture(scope="module")
def recordings(tmp_path_factory, basis):
    folder = tmp_path_factory.mktemp("rec")
    rng = np.random.default_rng(7)
    paths, t1s = [], []
    for k in range(9):
        t1 = float(rng.uniform(-35, 35))
        spec = basis.mean_db + t1 * basis.v1
        x = synthesize(spec, fs=FS, n_samples=int(1.0 * FS), level_db=-35.0, rng=np.random.default_rng(k)).signal
        p = folder / f"s{k}.wav"
        write_wav(p, x, FS)
        paths.append(p)
        t1s.append(t1)
    return folder, paths, np.array(t1s)


def test_compare_two_and_matrix(recordings, capsys):
    _, paths, t1 = recordings
    assert main(["compare", str(paths[0]), str(paths[1]), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["D"] == pytest.approx(abs(t1[0] - t1[1]), abs=0.3)
    assert main(["compare", *map(str, paths[:3])]) == 0
    text = capsys.readouterr().out
    assert "s0" in text and "s2" in text and "t1 units" in text


def test_compare_needs_two_files_and_valid_weights(recordings, capsys):
    _, paths, _ = recordings
    assert main(["compare", str(paths[0])]) == 2
    assert "at least two" in capsys.readouterr().err
    assert main(["compare", str(paths[0]), str(paths[1]), "--weights", "1,-1,0,0,0,0,0,0"]) == 2
    assert "non-negative" in capsys.readouterr().err
    assert main(["compare", str(paths[0]), str(paths[1]), "--weights", "1,2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 value(s) given; give 8, one per score component" in err


def test_compare_shows_whole_names_and_every_format(tmp_path, recordings, capsys):
    folder, paths, t1 = recordings
    # names that differ only at their very end (a 12-character label made every row look the same)
    deep = tmp_path / "a-long-folder-name-for-the-session-of-2026-11-24" / "scans"
    deep.mkdir(parents=True)
    long_names = []
    for k in range(3):
        target = deep / f"brushed-aluminium-mesh-scan-at-40mm-per-second-trial-{k}.wav"
        target.write_bytes(paths[k].read_bytes())
        long_names.append(str(target))
    assert main(["compare", "--recursive", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert all(name in text for name in long_names)  # whole, never cut (stdout is not a terminal)
    assert main(["compare", "-r", str(tmp_path), "--format", "csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "file_a,file_b,D" and len(lines) == 4
    a, b, d = lines[1].split(",")
    assert (a, b) == (long_names[0], long_names[1]) and float(d) == pytest.approx(abs(t1[0] - t1[1]), abs=0.3)
    assert main(["compare", "-r", str(tmp_path), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["files"] == long_names
    assert main(["compare", str(tmp_path)]) == 2
    assert "is a folder (add --recursive" in capsys.readouterr().err


def test_dissim_fit(recordings, capsys):
    folder, paths, t1 = recordings
    rng = np.random.default_rng(3)
    lines = ["file_a,file_b,rating"]
    for i in range(len(paths)):
        for j in range(i, len(paths)):
            r = 0.1 + 0.012 * abs(t1[i] - t1[j]) + rng.normal(0, 0.03)
            lines.append(f"{paths[i].name},{paths[j].name},{r:.4f}")
    (folder / "ratings.csv").write_text("\n".join(lines) + "\n")
    assert main(["dissim", "fit", str(folder / "ratings.csv"), "--splits", "4", "--cv", "5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["weights"][0] == pytest.approx(0.012, rel=0.2) and out["r2_mean"] > 0.6
    assert main(["dissim", "fit", str(folder / "ratings.csv"), "--splits", "2", "--cv", "5"]) == 0
    assert "R^2 alone" in capsys.readouterr().out


def test_dissim_fit_bad_csv(tmp_path, capsys):
    (tmp_path / "r.csv").write_text("file_a,file_b,rating\nx.wav,y.wav,0.2\n")
    assert main(["dissim", "fit", str(tmp_path / "r.csv")]) == 1  # a bad file: a runtime error
    assert "r.csv:2: recording 'x.wav' not found" in capsys.readouterr().err


def test_encode_decode_round_trip(basis, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_CACHE_DIR", str(tmp_path / "cache"))
    x = np.concatenate(
        [
            synthesize(basis.mean_db, fs=FS, n_samples=int(3 * FS), level_db=lv, rng=np.random.default_rng(s)).signal
            for s, lv in ((1, -42.0), (2, -34.0))
        ]
    )
    write_wav(tmp_path / "in.wav", x, FS)
    assert main(["encode", str(tmp_path / "in.wav"), "-o", str(tmp_path / "a.vbt"), "--json"]) == 0
    enc = json.loads(capsys.readouterr().out)
    assert enc["n_records"] == 2 and enc["bytes_per_second"] < 20
    assert enc["ratio_vs_pcm16_source"] > 300
    assert enc["quality"]["band_error_rms_db"] < 1.0
    assert (
        main(
            [
                "decode",
                str(tmp_path / "a.vbt"),
                "-o",
                str(tmp_path / "out.wav"),
                "--reference",
                str(tmp_path / "in.wav"),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "non-stationarity: original" in text and "vs 8-bit at 2.8 kHz" in text
    assert (tmp_path / "out.wav").stat().st_size > 1000
    (tmp_path / "bad.vbt").write_bytes((tmp_path / "a.vbt").read_bytes()[:-3])
    assert main(["decode", str(tmp_path / "bad.vbt"), "-o", str(tmp_path / "o2.wav")]) == 1
    assert "truncated" in capsys.readouterr().err
    assert not (tmp_path / "o2.wav").exists()


def test_encode_codes_a_non_stationary_recording_per_window(tmp_path, basis, capsys):
    fs = 2800.0
    x = synthesize(basis.mean_db, fs=fs, n_samples=int(6 * fs), level_db=-40.0, rng=np.random.default_rng(0)).signal
    ramp = x * 10 ** (np.linspace(-30, 0, x.size) / 20)
    src = tmp_path / "ramp.wav"
    write_wav(src, 0.5 * ramp / np.max(np.abs(ramp)), fs)
    assert main(["encode", str(src), "-o", str(tmp_path / "r.vbt"), "--json"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["segmentation"]["fell_back"] and not report["segmentation"]["segments"]
    assert report["segmentation"]["window_level_error_db"] > 10
    assert "not stationary" in captured.err and "coded every window instead" in captured.err
    assert report["quality"]["window_level_max_db"] < 6  # the windows' intensity survives
    assert main(["encode", str(src), "-o", str(tmp_path / "k.vbt"), "--json", "--keep-segments"]) == 0
    kept = json.loads(capsys.readouterr().out)
    assert kept["segmentation"]["segments"] and kept["quality"]["window_level_max_db"] > 10


def test_plot_spectrum_takes_a_folder_with_recursive(tmp_path, recordings):
    pytest.importorskip("matplotlib")
    import matplotlib.image as mpimg

    folder, paths, _ = recordings
    one, three = tmp_path / "one.png", tmp_path / "three.png"
    sub = tmp_path / "scans" / "deep"
    sub.mkdir(parents=True)
    for p in paths[:3]:
        (sub / p.name).write_bytes(p.read_bytes())
    assert main(["plot", "spectrum", str(paths[0]), "-o", str(one)]) == 0
    assert main(["plot", "spectrum", "-r", str(tmp_path / "scans"), "-o", str(three)]) == 0
    h1, h3 = mpimg.imread(one).shape[0], mpimg.imread(three).shape[0]
    assert 2.0 < h3 / h1 < 3.5  # one panel per recording found under the folder (plus one title and axis)
    assert main(["plot", "spectrum", str(tmp_path / "scans"), "-o", str(three)]) == 2  # a folder needs -r
