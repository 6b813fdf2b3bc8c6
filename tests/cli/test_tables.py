"""Tables of the CLI: whole names, middle elision on narrow terminals, JSON and CSV."""

from __future__ import annotations

import argparse
import csv
import io
import json

import numpy as np
import pytest

from vibsynth.cli import main
from vibsynth.cli._inputs import MAX_FILES, expand_recordings, wav_channel
from vibsynth.cli._table import Column, elide_middle, emit, format_table, output_format
from vibsynth.dsp.synthesis import synthesize
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import write_wav

COLUMNS = (Column("file", "file", name=True), Column("x", "value", lambda v: f"{v:.2f}"))


@pytest.mark.parametrize("seed", range(5))
def test_elided_names_keep_their_distinguishing_end(seed):
    rng = np.random.default_rng(seed)
    stem = "/data/" + "x" * int(rng.integers(20, 80)) + "/scan-"
    names = [stem + f"{k:03d}.wav" for k in rng.choice(1000, size=6, replace=False)]
    for width in (16, 24, 40):
        shown = [elide_middle(n, width) for n in names]
        assert all(len(s) <= width for s in shown)
        assert len(set(shown)) == len(names)  # still tells every row apart
        assert all(s.endswith(n[-8:]) for s, n in zip(shown, names))


def test_table_shows_whole_names_unless_the_terminal_is_narrow():
    rows = [{"file": f"/very/long/folder/name/for/a/session/scan-{k}.wav", "x": k / 3} for k in range(3)]
    whole = format_table(rows, COLUMNS)
    assert all(r["file"] in whole for r in rows)
    narrow = format_table(rows, COLUMNS, width=30)
    lines = narrow.splitlines()
    assert all(len(line) <= 30 for line in lines)
    assert [line.split()[0][-10:] for line in lines[1:]] == ["scan-0.wav", "scan-1.wav", "scan-2.wav"]
    assert "…" in lines[1]


def test_json_and_csv_carry_raw_values():
    rows = [{"file": "a,b.wav", "x": 1 / 3}, {"file": 'q"uote.wav', "x": np.float64(2.5)}]
    out = io.StringIO()
    emit(rows, COLUMNS, "csv", stream=out)
    parsed = list(csv.reader(io.StringIO(out.getvalue())))
    assert parsed == [["file", "x"], ["a,b.wav", repr(1 / 3)], ['q"uote.wav', "2.5"]]
    out = io.StringIO()
    emit(rows, COLUMNS, "json", stream=out)
    assert json.loads(out.getvalue()) == [{"file": "a,b.wav", "x": 1 / 3}, {"file": 'q"uote.wav', "x": 2.5}]


def test_json_flag_and_format_must_agree():
    assert output_format(argparse.Namespace(format=None, json=True)) == "json"
    assert output_format(argparse.Namespace(format="csv", json=False)) == "csv"
    with pytest.raises(argparse.ArgumentTypeError, match="disagree"):
        output_format(argparse.Namespace(format="csv", json=True))


def test_recursive_folders_are_sorted_and_bounded(tmp_path, monkeypatch):
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "deep").mkdir(parents=True)
    for rel in ("b/2.wav", "a/deep/1.csv", "a/0.wav", "a/notes.md"):
        (tmp_path / rel).write_text("")
    found = expand_recordings([tmp_path], recursive=True)
    assert [p.relative_to(tmp_path).as_posix() for p in found] == ["a/0.wav", "a/deep/1.csv", "b/2.wav"]
    with pytest.raises(ParameterError, match="is a folder"):
        expand_recordings([tmp_path], recursive=False)
    with pytest.raises(InputError, match="no such file or folder"):
        expand_recordings([tmp_path / "nothing"], recursive=True)
    monkeypatch.setattr("vibsynth.cli._inputs.MAX_FILES", 2)
    with pytest.raises(InputError, match="more than 2 recordings"):
        expand_recordings([tmp_path], recursive=True)
    assert MAX_FILES == 10_000


def test_wav_channels_are_counted_from_one():
    assert wav_channel("1") == 0 and wav_channel("2") == 1
    for bad in ("0", "-1", "x", "70000"):
        with pytest.raises(argparse.ArgumentTypeError, match="1 = the first"):
            wav_channel(bad)


def test_analyze_reads_the_second_channel_as_2(tmp_path, capsys, basis):
    fs = 3000.0
    quiet = synthesize(basis.mean_db, fs=fs, n_samples=3000, level_db=-50.0, rng=np.random.default_rng(1)).signal
    loud = synthesize(basis.mean_db, fs=fs, n_samples=3000, level_db=-30.0, rng=np.random.default_rng(2)).signal
    path = tmp_path / "two-channels.wav"
    write_wav(path, np.stack([quiet, loud], axis=1), fs)
    levels = []
    for channel in ("1", "2"):
        assert main(["analyze", str(path), "--channel", channel, "--format", "csv"]) == 0
        row = next(csv.DictReader(io.StringIO(capsys.readouterr().out)))
        levels.append(float(row["level_db"]))
    assert levels == [pytest.approx(-50.0, abs=0.1), pytest.approx(-30.0, abs=0.1)]


def test_devices_in_every_format(monkeypatch, capsys):
    from vibsynth.control.midi import adapter
    from vibsynth.engine import outputs

    apis = [{"index": 0, "name": "JACK Audio Connection Kit", "default_output_device": 1}]
    devices = [
        {
            "index": k,
            "name": f"system playback with a long descriptive name #{k}",
            "hostapi": 0,
            "max_output_channels": 2 * (k + 1),
            "default_samplerate": 48000.0,
            "default_low_output_latency": 0.00533,
        }
        for k in range(2)
    ]
    monkeypatch.setattr(outputs, "list_devices", lambda: (apis, devices))
    monkeypatch.setattr(adapter, "list_inputs", lambda: ["Keystation 49:0"])
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "system playback with a long descriptive name #0" in out and "JACK Audio Connection Kit" in out
    starred = [line for line in out.splitlines() if line.lstrip().startswith("*")]
    assert len(starred) == 1 and "#1" in starred[0] and "5.3" in starred[0]
    assert "0: Keystation 49:0" in out
    assert main(["devices", "--format", "csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [(r["index"], r["outputs"], r["default"]) for r in rows] == [("0", "2", "False"), ("1", "4", "True")]
    assert main(["devices", "--format", "json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["midi_inputs"] == ["Keystation 49:0"] and data["audio"][1]["latency_ms"] == pytest.approx(5.33)
