"""analyze / render / basis from the command line, including every bad-input case."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.cli import main
from vibsynth.formats.basis_file import load_basis

ROOT = Path(__file__).resolve().parents[2]


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "vibsynth", *args], cwd=ROOT, capture_output=True, text=True, timeout=120
    )


def test_render_then_analyze_round_trip(tmp_path, capsys):
    out = tmp_path / "t.wav"
    assert (
        main(
            [
                "render",
                "--balance",
                "-0.7",
                "--intensity",
                "0.6",
                "--seconds",
                "1",
                "--rate",
                "8000",
                "-o",
                str(out),
                "--seed",
                "3",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["analyze", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)[0]
    assert data["balance"] == pytest.approx(-0.7, abs=0.02)
    assert data["intensity_knob"] == pytest.approx(0.6, abs=0.005)
    assert len(data["scores"]) == 8 and len(data["band_db"]) == 30


@pytest.mark.parametrize("variant", ["S1", "S1:8", "S2:8", "M"])
def test_render_variants_from_a_recording(tmp_path, capsys, variant):
    src = tmp_path / "src.wav"
    main(
        [
            "render",
            "--balance",
            "0.8",
            "--intensity",
            "0.9",
            "--seconds",
            "1",
            "--rate",
            "4000",
            "-o",
            str(src),
            "--seed",
            "1",
        ]
    )
    out = tmp_path / "v.wav"
    assert main(["render", "--from", str(src), "--variant", variant, "--seconds", "1", "-o", str(out)]) == 0
    capsys.readouterr()
    main(["analyze", str(src), str(out), "--json"])
    a, b = json.loads(capsys.readouterr().out)
    assert b["level_db"] == pytest.approx(a["level_db"], abs=0.1)
    expected_t1 = {"S1": a["t1"], "S1:8": a["t1"], "S2:8": 0.0, "M": 0.0}[variant]
    assert b["t1"] == pytest.approx(expected_t1, abs=0.05)


def test_analyze_table_and_csv_input(tmp_path, capsys, rng):
    csv = tmp_path / "rec.csv"
    x = rng.standard_normal(3000) * 0.1
    csv.write_text("acc\n" + "\n".join(f"{v:.6f}" for v in x))
    assert main(["analyze", str(csv), "--rate", "3000"]) == 0
    out = capsys.readouterr().out
    assert "level dB" in out and "rec.csv" in out


def test_basis_fit_from_a_folder_of_recordings(tmp_path, capsys, basis, rng):
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.formats.recordings import write_wav

    folder = tmp_path / "recs"
    for i in range(12):
        scores = rng.uniform(-1, 1, 8) * basis.score_std
        sig = synthesize(basis.reconstruct(scores), fs=4000.0, n_samples=4000, level_db=-40, rng=rng).signal
        write_wav(folder / f"r{i:02d}.wav", sig, 4000.0)
    out = tmp_path / "b.yaml"
    assert main(["basis", "fit", str(folder), "-o", str(out)]) == 0
    fitted = load_basis(out)
    assert fitted.n_spectra == 12
    assert fitted.provenance["source_kind"] == "recordings"
    assert "explained variance" in capsys.readouterr().out


def test_basis_show_prints_the_default(capsys, basis):
    assert main(["basis", "show"]) == 0
    out = capsys.readouterr().out
    assert basis.id in out and "Culbertson" in out


def _write(path: Path, fs: int, data: np.ndarray) -> Path:
    wavfile.write(path, fs, data)
    return path


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda d: d / "missing.wav", "no such file"),
        (lambda d: (d / "junk.wav").write_bytes(b"RIFF0000WAVEjunk") and d / "junk.wav", "not a readable WAV"),
        (lambda d: _write(d / "nan.wav", 8000, np.full(8000, np.nan, dtype=np.float32)), "NaN"),
        (lambda d: _write(d / "silent.wav", 8000, np.zeros(8000, dtype=np.int16)), "silent"),
        (
            lambda d: _write(
                d / "short.wav", 8000, (np.random.default_rng(0).standard_normal(400) * 1000).astype(np.int16)
            ),
            "too short",
        ),
        (
            lambda d: _write(
                d / "lowrate.wav", 1000, (np.random.default_rng(0).standard_normal(2000) * 1000).astype(np.int16)
            ),
            "too low",
        ),
        (lambda d: (d / "x.mp3").write_bytes(b"ID3") and d / "x.mp3", "unsupported file type"),
        (lambda d: (d / "c.csv").write_text("1\n2\n") and d / "c.csv", "--rate"),
    ],
)
def test_bad_recordings_give_one_line_and_exit_2(tmp_path, make, needle):
    path = make(tmp_path)
    result = run_cli("analyze", str(path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vibsynth: error:"), result.stderr
    assert needle in lines[0]
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize(
    "args, needle",
    [
        (["render", "--balance", "nan", "--intensity", "0.5", "-o", "x.wav"], "not a finite number"),
        (["render", "--balance", "0", "--intensity", "1.5", "-o", "x.wav"], "outside [0, 1]"),
        (["render", "--balance", "0", "--intensity", "0.5", "--rate", "1000", "-o", "x.wav"], "outside [2400"),
        (["render", "--balance", "0", "--intensity", "0.5", "--seconds", "-1", "-o", "x.wav"], "outside (0"),
        (["render", "--balance", "0", "-o", "x.wav"], "needs --intensity"),
    ],
)
def test_bad_arguments_exit_2_without_traceback(tmp_path, args, needle):
    result = run_cli(*[a if a != "x.wav" else str(tmp_path / "x.wav") for a in args])
    assert result.returncode == 2
    assert needle in result.stderr and "Traceback" not in result.stderr
