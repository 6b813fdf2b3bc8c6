"""Every sub-command, fed bad arguments and bad files: one line ``vibsynth: error: ...``, exit 2 or 1, no traceback.

Exit 2 is a usage error (the command line itself is wrong); exit 1 is a runtime error (a
file that is missing, unreadable or malformed, a device, a refused write). The table below
is the contract: a new sub-command or option adds its rows.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibsynth.cli import main

USAGE, RUNTIME = 2, 1


@pytest.fixture(scope="module")
def files(tmp_path_factory, basis):
    """Good and bad inputs, made once."""
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.formats.recordings import write_wav

    d = tmp_path_factory.mktemp("bad-inputs")
    good = d / "good.wav"
    x = synthesize(basis.mean_db, fs=8000.0, n_samples=8000, level_db=-40.0, rng=np.random.default_rng(0)).signal
    write_wav(good, x, 8000.0)
    (d / "junk.wav").write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    (d / "empty.wav").write_bytes(b"")
    (d / "no-fmt.wav").write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunk" + bytes(64))  # scipy: UnboundLocalError
    (d / "folder").mkdir()
    header = b"RIFF" + struct.pack("<I", 36) + b"WAVEfmt " + struct.pack("<IHHIIHH", 16, 1, 0, 8000, 0, 0, 16)
    (d / "zero-channels.wav").write_bytes(header + b"data" + struct.pack("<I", 0))
    (d / "bomb.yaml").write_text("a: &a [x, x]\nb: &b [*a, *a]\nc: [*b, *b]\n")
    (d / "broken.yaml").write_text("audio:\n  rate: [unclosed\n")
    (d / "binary.yaml").write_bytes(bytes(range(256)) * 4)
    (d / "ratings.csv").write_text("file_a,file_b,rating\nnope.wav,nope2.wav,0.5\n")
    (d / "junk.vbt").write_bytes(b"VBTR" + bytes(60))
    (d / "junk.mid").write_bytes(b"MThd" + bytes(20))
    (d / "user.yaml").write_text("version: 1\n")
    (d / "truncated.ahap").write_text('{"Version": 1, "Pattern": [{"Event": {"Time": 0.0, "EventType": "Hap')
    (d / "nan.ahap").write_text('{"Pattern": [{"Event": {"Time": NaN, "EventType": "HapticTransient"}}]}')
    (d / "huge.ahap").write_text(
        '{"Pattern": [' + '{"Event": {"Time": 0, "EventType": "HapticTransient"}},' * 120_000 + "]}"
    )
    (d / "bad.haptic").write_text(
        '{"version": {"major": 1}, "signals": {"continuous": {"envelopes": {"amplitude": []}}}}'
    )
    (d / "bad-clip.yaml").write_text("duration_ms: 100\nkeyframes: [{t_ms: 0, intensity: 2, balance: 0}]\n")
    return d


def _cases():
    """(argv with {dir} placeholders, expected exit code)."""
    return [
        # the command line itself is wrong
        ("nosuchcommand", USAGE),
        ("analyze", USAGE),
        ("analyze {dir}/good.wav --channel 0", USAGE),
        ("analyze {dir}/good.wav --rate -5", USAGE),
        ("analyze {dir}/good.wav --format xml", USAGE),
        ("render --balance x --intensity 0.5 -o {dir}/o.wav", USAGE),
        ("render --balance 0 --intensity 0.5 --seconds nan -o {dir}/o.wav", USAGE),
        ("render --balance 0 --intensity 0.5 --seconds 1e9 -o {dir}/o.wav", USAGE),
        ("render --balance 0 --intensity 0.5 --seed -1 -o {dir}/o.wav", USAGE),
        ("render --balance 0 --intensity 7 -o {dir}/o.wav", USAGE),
        ("compare {dir}/good.wav", USAGE),
        ("compare {dir}/good.wav {dir}/good.wav --weights 1,2", USAGE),
        ("compare {dir}/good.wav {dir}/good.wav --weights a,b", USAGE),
        ("send", USAGE),
        ("send /vibsynth/intensity 0.5 --wait-reply nan", USAGE),
        ("send /vibsynth/intensity 0.5 --wait-reply -1", USAGE),
        ("send /vibsynth/intensity 0.5 --from-port 99999", USAGE),
        ("send /vibsynth/intensity 0.5 --port 0", USAGE),
        ("status --port 99999", USAGE),
        ("status --timeout 0", USAGE),
        ("monitor --count 0", USAGE),
        ("serve --seconds -1", USAGE),
        ("serve --channels 0", USAGE),
        ("serve --studio-token short", USAGE),
        ("serve --studio-token has/slash/in/it/x", USAGE),
        ("serve --studio-port 70000", USAGE),
        ("studio --no-studio --seconds 0.1", USAGE),
        ("serve --layout ../glove --seconds 0.1", USAGE),
        ("serve --output null --layout glov --channels 6 --seconds 0.1", USAGE),
        ("serve --output null --layout glove --seconds 0.1", USAGE),
        ("encode {dir}/good.wav -o {dir}/o.vbt --bits 99", USAGE),
        ("dissim fit {dir}/ratings.csv --splits 0", USAGE),
        ("preset show", USAGE),
        ("config show no.such.key", USAGE),
        ("clip show", USAGE),
        ("clip show nosuchclip", USAGE),
        ("clip import {dir}/good.wav", USAGE),
        ("clip import {dir}/nan.ahap --name ../x", USAGE),
        ("clip import {dir}/nan.ahap --from wav", USAGE),
        ("clip export nosuchclip -o {dir}/o.ahap", USAGE),
        ("clip export heartbeat --format wav", USAGE),
        ("clip play impakt --port 1 --timeout 0.2 --gain nan", USAGE),
        ("clip play impact --rate 0", USAGE),
        ("clip play impact --loops 10001", USAGE),
        ("clip play impact --at 11", USAGE),
        ("clip play impact --channel 0", USAGE),
        ("clip stop --release -1", USAGE),
        ("render --clip impakt -o {dir}/o.wav", USAGE),
        ("render --clip rain --loops 0 -o {dir}/o.wav", USAGE),
        ("render --clip impact --gain 5 -o {dir}/o.wav", USAGE),
        ("render --balance 0 --intensity 0.5 --loops 2 -o {dir}/o.wav", USAGE),
        ("lab plan dissimilarity --stimuli renders:1", USAGE),
        ("lab plan dissimilarity --stimuli renders --seed -1", USAGE),
        ("lab plan dissimilarity --stimuli renders --seed 18446744073709551616", USAGE),
        ("lab plan abx --stimuli renders", USAGE),
        ("lab sessions --format xml", USAGE),
        ("lab --no-studio --output null --seconds 0.1", USAGE),
        # a file is missing, unreadable or malformed, or cannot be written
        ("analyze {dir}/missing.wav", RUNTIME),
        ("analyze {dir}/junk.wav", RUNTIME),
        ("analyze {dir}/empty.wav", RUNTIME),
        ("analyze {dir}/folder", USAGE),  # a folder without --recursive
        ("analyze {dir}/zero-channels.wav", RUNTIME),
        ("analyze {dir}/good.wav --basis {dir}/bomb.yaml", RUNTIME),
        ("analyze {dir}/good.wav --basis {dir}/broken.yaml", RUNTIME),
        ("analyze {dir}/good.wav --basis {dir}/binary.yaml", RUNTIME),
        ("render --from {dir}/junk.wav -o {dir}/o.wav", RUNTIME),
        ("render --balance 0 --intensity 0.5 --seconds 1 -o {dir}/folder", RUNTIME),
        ("render --balance 0 --intensity 0.5 --seconds 1 -o {dir}/missing-dir/o.wav", RUNTIME),
        ("render --midi {dir}/junk.mid -o {dir}/o.wav", RUNTIME),
        ("compare {dir}/good.wav {dir}/junk.wav", RUNTIME),
        ("decode {dir}/junk.vbt -o {dir}/o.wav", RUNTIME),
        ("encode {dir}/junk.wav -o {dir}/o.vbt", RUNTIME),
        ("dissim fit {dir}/ratings.csv", RUNTIME),
        ("basis show --basis {dir}/broken.yaml", RUNTIME),
        ("config check {dir}/broken.yaml", RUNTIME),
        ("config check {dir}/bomb.yaml", RUNTIME),
        ("config check {dir}/binary.yaml", RUNTIME),
        ("preset from-recording {dir}/junk.wav --name x", RUNTIME),
        ("analyze {dir}/no-fmt.wav", RUNTIME),
        ("serve --config {dir}/bomb.yaml --seconds 0.1", RUNTIME),
        ("serve --output wav -o {dir}/missing-dir/x.wav --seconds 0.1", RUNTIME),
        ("clip import {dir}/truncated.ahap", RUNTIME),
        ("clip import {dir}/nan.ahap", RUNTIME),
        ("clip import {dir}/huge.ahap", RUNTIME),
        ("clip import {dir}/missing.ahap", RUNTIME),
        ("clip import {dir}/bad.haptic", RUNTIME),
        ("clip import {dir}/junk.wav --from haptic", RUNTIME),
        ("clip validate {dir}/bad-clip.yaml", RUNTIME),
        ("clip validate {dir}/bomb.yaml", RUNTIME),
        ("clip validate {dir}/binary.yaml", RUNTIME),
        ("clip export heartbeat -o {dir}/good.wav/x.ahap", RUNTIME),
        ("clip play impact --port 1 --timeout 0.2", RUNTIME),  # no server there
        ("clip stop --port 1 --timeout 0.2", RUNTIME),
        ("render --clip impact -o {dir}/missing-dir/o.wav", RUNTIME),
        ("lab plan dissimilarity --stimuli {dir}/folder", RUNTIME),  # no WAVs
        ("lab plan dissimilarity --stimuli {dir}", RUNTIME),  # broken WAVs
        ("lab plan dissimilarity --stimuli presets:nope", RUNTIME),
        ("lab analyze {dir}/folder", RUNTIME),  # not a session
        ("lab analyze ../escape", RUNTIME),
        ("lab equalise {dir}/folder -o {dir}/eq", RUNTIME),
    ]


@pytest.mark.parametrize("argv, expected", _cases(), ids=[c[0] for c in _cases()])
def test_one_line_and_the_right_exit_code(argv, expected, files, capsys, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_CONFIG", str(files / "user.yaml"))
    monkeypatch.setenv("XDG_DATA_HOME", str(files / "data"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(files / "cache"))
    args = argv.format(dir=files).split()
    try:
        code = main(args)
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("vibsynth: warning:")]
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("vibsynth: error: "), err
    assert code == expected, f"exit {code}, expected {expected}: {lines[0]}"


def test_closing_the_pipe_early_is_quiet(tmp_path):
    """``vibsynth ... | head -1``: no BrokenPipeError, whatever the command was printing."""
    env = dict(os.environ, VIBSYNTH_CONFIG=str(tmp_path / "none.yaml"), XDG_DATA_HOME=str(tmp_path))
    for argv in (["preset", "list"], ["--help"], ["config", "show"]):
        proc = subprocess.Popen(
            [sys.executable, "-m", "vibsynth", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
        )
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.readline()
        proc.stdout.close()  # what `head -1` does
        err = proc.stderr.read().decode()
        proc.wait(timeout=30)
        assert "Traceback" not in err and "BrokenPipe" not in err, err


def test_outputs_respect_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        assert (
            main(["render", "--balance", "0", "--intensity", "0.5", "--seconds", "1", "-o", str(tmp_path / "a.wav")])
            == 0
        )
    finally:
        os.umask(old)
    assert (Path(tmp_path / "a.wav").stat().st_mode & 0o777) == 0o644
