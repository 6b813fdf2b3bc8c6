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
def test_bad_recordings_give_one_line_and_exit_1(tmp_path, make, needle):
    path = make(tmp_path)
    result = run_cli("analyze", str(path))
    assert result.returncode == 1  # a bad file is a runtime error (2 is for a bad command line)
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
        (["render", "--balance", "0", "--intensity", "0.5", "--seed", "-1", "-o", "x.wav"], "seed -1 is outside"),
        (["render", "--balance", "0", "--intensity", "0.5", "--seed", "1.5", "-o", "x.wav"], "'1.5' is not an integer"),
        (["render", "--from", "x.wav", "--channel", "0", "-o", "x.wav"], "channel 0 is outside 1..65535"),
    ],
)
def test_bad_arguments_exit_2_without_traceback(tmp_path, args, needle):
    result = run_cli(*[a if a != "x.wav" else str(tmp_path / "x.wav") for a in args])
    assert result.returncode == 2
    assert needle in result.stderr and "Traceback" not in result.stderr


# --------------------------------------------------------------------------- render: bad files, exit 1
def _raw_wav(bits: int, data: bytes, *, channels: int = 1, fs: int = 8000) -> bytes:
    import struct

    align = (bits + 7) // 8 * channels
    fmt = struct.pack("<HHIIHH", 1, channels, fs, fs * align, align, bits)
    body = b"WAVEfmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(data)) + data
    return b"RIFF" + struct.pack("<I", len(body)) + body


def test_render_from_a_bad_recording_is_one_line_and_exit_1(tmp_path):
    (tmp_path / "c0.wav").write_bytes(_raw_wav(16, bytes(400), channels=0))
    _write(tmp_path / "stereo.wav", 8000, (np.random.default_rng(0).standard_normal((8000, 2)) * 0.1).astype("<f4"))
    for args, needle in (
        (["--from", str(tmp_path / "c0.wav")], "c0.wav: not a readable WAV file (its header says 0 channels)"),
        (["--from", str(tmp_path / "missing.wav")], "missing.wav: no such file"),
        (["--from", str(tmp_path / "stereo.wav"), "--channel", "3"], "channel 3 (index 2) does not exist"),
        (["--balance", "0", "--intensity", "0.5", "--basis", str(tmp_path / "nope.yaml")], "nope.yaml"),
    ):
        result = run_cli("render", *args, "-o", str(tmp_path / "out.wav"))
        assert result.returncode == 1, (args, result.stderr)
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("vibsynth: error: ") and needle in lines[0], result.stderr
        assert not (tmp_path / "out.wav").exists()
    result = run_cli("render", "--from", str(tmp_path / "stereo.wav"), "--channel", "2", "-o", str(tmp_path / "o.wav"))
    assert result.returncode == 0, result.stderr


def test_render_from_an_8_bit_recording_reads_it_at_its_true_level(tmp_path, capsys):
    """The 8-bit container is unsigned: a full-scale 8-bit square renders exactly as the same square in float."""
    square = np.where(np.arange(8000) % 80 < 40, 255, 0).astype(np.uint8)  # 100 Hz, full scale
    (tmp_path / "sq8.wav").write_bytes(_raw_wav(8, square.tobytes()))
    (tmp_path / "sq7.wav").write_bytes(_raw_wav(7, (square & 0xFE).tobytes()))  # 7 bits, left-justified
    _write(tmp_path / "sqf.wav", 8000, ((square.astype(np.float64) - 128) / 128).astype(np.float32))
    outs = {}
    for name in ("sq8", "sq7", "sqf"):
        out = tmp_path / f"{name}-out.wav"
        args = ["render", "--from", str(tmp_path / f"{name}.wav"), "--seconds", "0.5", "--seed", "4", "-o", str(out)]
        assert main(args) == 0
        outs[name] = wavfile.read(out)[1]
    capsys.readouterr()
    np.testing.assert_array_equal(outs["sq8"], outs["sqf"])
    assert 20 * np.log10(np.abs(outs["sq7"]).max() / np.abs(outs["sqf"]).max()) == pytest.approx(0.0, abs=0.15)
    assert main(["analyze", str(tmp_path / "sq8.wav"), str(tmp_path / "sqf.wav"), "--json"]) == 0
    a, b = json.loads(capsys.readouterr().out)
    assert a["level_db"] == pytest.approx(b["level_db"], abs=1e-9)


# --------------------------------------------------------------------------- render: balance beyond the basis
def test_render_warns_when_the_balance_saturates(tmp_path, capsys, basis):
    from vibsynth.cli.render import reachable_balance
    from vibsynth.dsp.synthesis import SpectralShaper

    shaper = SpectralShaper(fs=8000.0, n_samples=8000, centres=basis.centres_hz, order=basis.filter_order)
    low, high = reachable_balance(shaper, basis)
    assert low == pytest.approx(-5.45, abs=0.05) and high == pytest.approx(2.80, abs=0.05)  # docs/science.md
    results = {}
    for balance in (3.0, high - 0.2, 0.0, low + 0.2, -6.0):
        out = tmp_path / f"b{balance:g}.wav"
        args = ["render", "--balance", f"{balance:g}", "--intensity", "0.7", "--seconds", "1", "--rate", "8000"]
        assert main([*args, "--seed", "2", "-o", str(out)]) == 0
        err = capsys.readouterr().err
        assert main(["analyze", str(out), "--json"]) == 0
        results[balance] = (err, json.loads(capsys.readouterr().out)[0]["balance"])
    for balance, (err, measured) in results.items():
        if low <= balance <= high:
            assert err == "" and measured == pytest.approx(balance, abs=0.02)
        else:
            edge = high if balance > high else low
            assert err == (
                f"vibsynth: warning: balance {balance:g} is beyond what basis {basis.id} can render "
                f"(reachable: {low:+.2f} .. {high:+.2f}, at intensity 0.7 as at any); rendered at {edge:+.2f}\n"
            )
            assert measured == pytest.approx(edge, abs=0.02)


# --------------------------------------------------------------------------- progress bar
def _run_in_pty(args: list[str], cwd: Path) -> bytes:
    """Run the CLI with stdin, stdout and stderr on a pseudo-terminal; everything it printed."""
    import os
    import pty
    import select

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "vibsynth", *args], cwd=cwd, stdin=slave, stdout=slave, stderr=slave, close_fds=True
    )
    os.close(slave)
    out = b""
    try:
        while True:
            ready, _, _ = select.select([master], [], [], 120)
            if not ready:
                break  # a hung child fails the assertions below
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            out += chunk
    finally:
        os.close(master)
        proc.wait(timeout=120)
    assert proc.returncode == 0, out.decode(errors="replace")
    return out


def _progress_commands(tmp_path: Path) -> dict[str, list[str]]:
    import mido

    from vibsynth.dsp.codec import Quantizer, encode_trajectory
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.formats import vbt
    from vibsynth.formats.basis_file import default_basis

    config = tmp_path / "config.yaml"
    config.write_text(f"bank:\n  cache_dir: {tmp_path / 'cache'}\n  loop_seconds: 0.5\n  levels: 5\n")
    mid = mido.MidiFile(ticks_per_beat=480)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.Message("note_on", note=60, velocity=100, time=0))
    track.append(mido.Message("note_off", note=60, time=960))
    mid.save(tmp_path / "x.mid")
    basis = default_basis()
    x = synthesize(basis.mean_db, fs=2800.0, n_samples=8400, level_db=-40.0, rng=np.random.default_rng(1)).signal
    traj = encode_trajectory(x, fs=2800.0, basis=basis)
    vbt.write_vbt(tmp_path / "x.vbt", traj, Quantizer.fit(traj))
    return {
        "render": ["render", "--balance", "0", "--intensity", "0.5", "--seconds", "20", "--rate", "8000"],
        "midi": ["render", "--midi", str(tmp_path / "x.mid"), "--rate", "8000", "--config", str(config)],
        "decode": ["decode", str(tmp_path / "x.vbt"), "--config", str(config)],
    }


@pytest.mark.parametrize("kind", ["render", "midi", "decode"])
def test_progress_bar_on_a_terminal_only(tmp_path, kind):
    command = _progress_commands(tmp_path)[kind]
    label = b"decode" if kind == "decode" else b"render"
    # on a terminal: a bar that ends at 100 %, then the summary
    shown = _run_in_pty([*command, "-o", str(tmp_path / "a.wav")], ROOT)
    bars = [part for part in shown.split(b"\r") if part.startswith(label + b":")]
    assert bars and bars[-1].startswith(label + b": 100%|") and b"|" in bars[-1], shown
    assert all(int(bar.split(b"%")[0].split(b":")[1]) <= 100 for bar in bars)
    assert (tmp_path / "a.wav").stat().st_size > 1000
    # --quiet on a terminal: neither bar nor summary
    quiet = _run_in_pty([*command, "-o", str(tmp_path / "b.wav"), "--quiet"], ROOT)
    assert b"%|" not in quiet and b"\r" not in quiet.replace(b"\r\n", b"") and b"wrote" not in quiet, quiet
    assert (tmp_path / "b.wav").read_bytes()[:4] == b"RIFF"
    # piped: no bar, no carriage return, the summary only
    piped = run_cli(*command, "-o", str(tmp_path / "c.wav"))
    assert piped.returncode == 0 and piped.stderr == "", piped.stderr
    assert "\r" not in piped.stdout and "%|" not in piped.stdout and str(tmp_path / "c.wav") in piped.stdout


def test_progress_bar_redraws_at_most_10_times_a_second():
    """1000 blocks in one second of a fake clock: at most 10 redraws plus the first and the last."""
    import io

    from vibsynth.cli._progress import RenderProgress

    stream = io.StringIO()
    clock = [1000.0]
    progress = RenderProgress("render", 1_000_000, 48000.0, stream=stream, enabled=True)
    progress._bar._time = lambda: clock[0]
    progress._bar.start_t = progress._bar.last_print_t = clock[0]
    for block in range(1, 1001):
        clock[0] += 0.001
        progress(block * 1000, 1_000_000)
    progress.close()
    draws = [part for part in stream.getvalue().split("\r") if part]
    assert 5 <= len(draws) <= 12, draws  # throttled, yet moving
    assert draws[-1].startswith("render: 100%|") and draws[-1].rstrip().endswith("]")
    # quiet, or not a terminal: nothing at all
    silent = io.StringIO()
    for quiet in (True, False):
        progress = RenderProgress("render", 1000, 100.0, quiet=quiet, stream=silent)
        progress(1000, 1000)
        progress.close()
    assert silent.getvalue() == ""


def test_analyze_profile_reports_the_calibrated_intensity(tmp_path, capsys, monkeypatch, rng):
    import yaml

    from vibsynth.dsp.felt_intensity import profile_weighting
    from vibsynth.dsp.intensity import intensity_level_db
    from vibsynth.formats.recordings import write_wav

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    folder = tmp_path / "cfg" / "vibsynth" / "actuators"
    folder.mkdir(parents=True)
    response = [[10.0, -20.0], [60.0, 6.0], [150.0, 0.0], [1000.0, 0.0]]
    weighting = [[10.0, -40.0], [100.0, -20.0], [300.0, 0.0], [600.0, -20.0], [1000.0, -40.0]]
    doc = {"name": "dev", "absolute": True, "response": response, "weighting": weighting, "band_hz": [250, 360]}
    (folder / "dev.yaml").write_text(yaml.safe_dump(doc))
    wav = tmp_path / "a.wav"
    x = rng.standard_normal(24000) * 0.05
    write_wav(wav, x, 8000.0)
    assert main(["analyze", str(wav), "--profile", "dev", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)[0]
    want = profile_weighting(response, weighting, [250, 360]).level_db(x.astype(np.float32), fs=8000.0)
    assert row["level_db"] == pytest.approx(want, abs=0.01)
    assert abs(row["level_db"] - intensity_level_db(x, fs=8000.0)) > 0.5
    assert row["intensity"] == "250-360 Hz (profile dev's weighting)"
    assert main(["analyze", str(wav), "--profile", "dev"]) == 0
    assert "level: intensity in 250-360 Hz (profile dev's weighting)" in capsys.readouterr().out
    assert main(["analyze", str(wav), "--profile", "nope"]) != 0
    err = capsys.readouterr().err
    assert err.startswith("vibsynth: error: unknown actuator profile 'nope'") and "Traceback" not in err
