"""Every sub-command, fed bad arguments and bad files: one line ``vibsynth: error: ...``, exit 2 or 1, no traceback.

Exit 2 is a usage error (the command line itself is wrong); exit 1 is a runtime error (a
file that is missing, unreadable or malformed, a device, a refused write). The table below
is the contract: a new sub-command or option adds its rows.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vibsynth.cli import EXIT_PIPE, main

USAGE, RUNTIME = 2, 1
ROOT = Path(__file__).resolve().parents[2]


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


# ---------------------------------------------------------------------- a reader that leaves
#: The pipe's size in the closed-pipe tests: the smallest Linux allows (a page), so that a
#: full pipe, where the next write waits, takes little filling.
PIPE_SIZE = 4096
#: Commands with more to print than a --help, and the bare command (its help, exit 2).
OUTPUTS = [["preset", "list"], ["config", "show"], ["clip", "list"], [], ["--version"]]
#: What the during/after cases run: a help shorter than the pipe, one longer, the outputs.
SAMPLE = [["--help"], ["lab", "--help"], *OUTPUTS]


def _no_noise(stderr: str) -> bool:
    """Nothing about the closed pipe: no traceback, no ``Exception ignored``, no error line."""
    return not any(word in stderr for word in ("Traceback", "Exception ignored", "BrokenPipe", "vibsynth: error"))


def _every_help() -> list[list[str]]:
    """``[--help]``, ``[serve, --help]``, ``[preset, list, --help]``, ...: every parser's help."""
    import argparse

    from vibsynth.cli import build_parser

    def walk(parser: argparse.ArgumentParser, path: list[str]):
        yield [*path, "--help"]
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, [*path, name])

    return list(walk(build_parser(), []))


def _writing_to_stdout(pid: int) -> bool:
    """The process waits in a system call on fd 1 (with the pipe full: a write)."""
    try:
        fields = Path(f"/proc/{pid}/syscall").read_text().split()
    except OSError:
        return False
    return len(fields) > 1 and fields[0] != "running" and fields[1] == "0x1"


def _run_with_reader_leaving(argv: list[str], when: str) -> dict:
    """Fork ``vibsynth ARGV`` with stdout on a pipe whose reader leaves ``when``; what it did.

    before: the read end is closed before the command starts (its first write is refused;
    for a --help, that write is the flush at exit). during: the pipe is full, the reader
    leaves while the command waits in its first write. after: the reader leaves once the
    command's first writes are in the pipe and it waits to write more, or has ended (a
    --help shorter than the pipe is one write). Runs in the process started by
    :func:`_drive`; the child
    ends as the console script does (``sys.exit(main())``, then Python's flush at exit),
    with stderr in a file.
    """
    import fcntl
    import tempfile
    import termios

    from vibsynth.cli import main

    r, w = os.pipe()
    fcntl.fcntl(w, fcntl.F_SETPIPE_SZ, PIPE_SIZE)
    size = fcntl.fcntl(w, fcntl.F_GETPIPE_SZ)
    filled = size if when == "during" else 0
    os.write(w, b"\0" * filled)
    if when == "before":
        os.close(r)
    err = tempfile.TemporaryFile()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the command: fd 1 the pipe's write end, fd 2 the file
        if when != "before":
            os.close(r)
        os.dup2(w, 1)
        os.dup2(err.fileno(), 2)
        sys.exit(main(argv))  # up through every frame: Python exits as after the console script
    os.close(w)
    waited, delivered, status = False, 0, None
    if when != "before":
        deadline = time.monotonic() + 20
        while not (waited := _writing_to_stdout(pid)) and time.monotonic() < deadline:
            done, ended = os.waitpid(pid, os.WNOHANG)
            if done:
                status = ended
                break
            time.sleep(0.002)
        delivered = struct.unpack("i", fcntl.ioctl(r, termios.FIONREAD, b"\0\0\0\0"))[0] - filled
        os.close(r)
    if status is None:
        status = os.waitpid(pid, 0)[1]
    err.seek(0)
    return {
        "argv": argv,
        "when": when,
        "code": os.waitstatus_to_exitcode(status),
        "stderr": err.read().decode(),
        "waited": waited,
        "delivered": delivered,
    }


def _drive(cases: list) -> None:  # pragma: no cover - the driver process of the tests below
    import gc

    from vibsynth.cli import build_parser

    build_parser()  # every command imported once, before the forks
    gc.freeze()  # the children's exits then touch (copy) fewer pages
    results = [_run_with_reader_leaving(argv, when) for argv, when in cases]
    sys.stdout.write(json.dumps(results))


def _user_env(tmp_path: Path, **env: str) -> dict[str, str]:
    """A user's environment: no PYTHON* (Python buffers stdout on a pipe), a config of its own."""
    (tmp_path / "user.yaml").write_text("version: 1\n")
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIBSYNTH_"))}
    clean.update(VIBSYNTH_CONFIG=str(tmp_path / "user.yaml"), XDG_DATA_HOME=str(tmp_path), HOME=str(tmp_path))
    return {**clean, **env}


def _drive_in_a_process(cases: list, tmp_path: Path, **env: str) -> list[dict]:
    """:func:`_drive` in a fresh Python with the user's environment (no PYTHONUNBUFFERED) plus ``env``."""
    code = f"from tests.cli.test_no_traceback import _drive; _drive({json.dumps(cases)})"
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=_user_env(tmp_path, **env),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    results = json.loads(proc.stdout)
    assert [[r["argv"], r["when"]] for r in results] == cases
    return results


def _assert_quiet(result: dict, buffered: bool = True) -> None:
    """Nothing on stderr about the pipe; exit 141, or 0 when all was written before the reader left.

    Unbuffered, Python writes a print with one write(2) and drops what a partial one left
    over: a command whose reader left in the middle of its last print sees no error (exit 0).
    """
    quiet = result["stderr"] == "" if "--help" in result["argv"] else _no_noise(result["stderr"])
    assert quiet, result
    if result["when"] == "during":  # refused inside the first write
        assert result["waited"] and result["delivered"] == 0, result
    if result["when"] == "after":  # the first write went through
        assert result["delivered"] > 0, result
    if result["when"] != "after":
        assert result["code"] == EXIT_PIPE, result
    elif not result["waited"]:  # it had written everything: its own code (the bare command's is 2)
        assert result["code"] == (0 if result["argv"] else USAGE), result
    else:
        assert result["code"] in ((EXIT_PIPE,) if buffered else (EXIT_PIPE, 0)), result


LINUX = pytest.mark.skipif(sys.platform != "linux", reason="sets the pipe's size and reads /proc (Linux)")


@LINUX
def test_every_help_with_its_reader_gone_before_the_exit_flush_is_quiet(tmp_path):
    """Each parser's --help (and the longer outputs) into a pipe whose reader has left: exit 141, stderr empty.

    Python buffers stdout on a pipe, so a --help is written by the last flush: the held-out
    ``Exception ignored in: <_io.TextIOWrapper name='<stdout>'>`` came from that flush at exit.
    """
    helps = _every_help()
    assert len(helps) > 40 and ["preset", "list", "--help"] in helps
    for result in _drive_in_a_process([[argv, "before"] for argv in helps + OUTPUTS], tmp_path):
        _assert_quiet(result)


@LINUX
@pytest.mark.parametrize("buffering", ["buffered", "unbuffered"])
def test_a_reader_leaving_during_or_after_the_first_write_is_quiet(buffering, tmp_path):
    """``vibsynth ... | head``: the reader leaves before, during or after the command's first write.

    Unbuffered (PYTHONUNBUFFERED=1), every print is a write and argparse's would drop the error.
    """
    whens = ("during", "after") if buffering == "buffered" else ("before", "during", "after")
    cases = [[argv, when] for argv in SAMPLE for when in whens]
    results = _drive_in_a_process(cases, tmp_path, **({"PYTHONUNBUFFERED": "1"} if buffering == "unbuffered" else {}))
    for result in results:
        _assert_quiet(result, buffered=buffering == "buffered")
    refused_after = [r["argv"] for r in results if r["when"] == "after" and r["code"] == EXIT_PIPE]
    assert ["config", "show"] in refused_after  # longer than the pipe: a later write was refused


def test_the_console_script_with_its_reader_gone_is_quiet(tmp_path):
    """The installed ``vibsynth`` (else ``python -m vibsynth``), the reader gone before the exit flush."""
    script = Path(sys.executable).with_name("vibsynth")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "vibsynth"]
    env = _user_env(tmp_path)
    r, w = os.pipe()
    os.close(r)
    proc = subprocess.run([*command, "--help"], stdout=w, stderr=subprocess.PIPE, env=env, timeout=60)
    os.close(w)
    assert (proc.returncode, proc.stderr.decode()) == (EXIT_PIPE, "")
    with subprocess.Popen([*command, "config", "show"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env) as p:
        assert p.stdout is not None and p.stderr is not None
        assert p.stdout.readline()  # what `head -1` does
        p.stdout.close()
        err = p.stderr.read().decode()
    assert p.returncode in (0, EXIT_PIPE) and _no_noise(err), err


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


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
@pytest.mark.parametrize("argv", [["--help"], ["config", "show"]])
def test_a_full_disk_on_stdout_is_one_line(argv, tmp_path, capsys, monkeypatch):
    """``vibsynth ... > /dev/full``: one error line, exit 1, nothing left for the flush at exit."""
    (tmp_path / "user.yaml").write_text("version: 1\n")
    monkeypatch.setenv("VIBSYNTH_CONFIG", str(tmp_path / "user.yaml"))
    full = open("/dev/full", "w")  # block-buffered, as stdout on a file
    monkeypatch.setattr(sys, "stdout", full)
    try:
        code = main(argv)
    except SystemExit as exc:  # --help
        code = exc.code
    full.close()  # what Python's exit does: it writes what is left (now into /dev/null)
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("vibsynth: error")]
    assert code == RUNTIME and len(errors) == 1 and "No space left on device" in errors[0], errors
