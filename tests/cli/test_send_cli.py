"""``vibsynth send`` against a real OSC server (in-process, fake engine) and a silent port."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.cli import main
from vibsynth.cli.send import prefix_of
from vibsynth.control.osc.server import OscServer


@pytest.fixture
def served():
    ctl = make_controller(2)
    server = OscServer(ctl, port=0)
    server.start()
    try:
        yield ctl, str(server.port)
    finally:
        server.stop()


@pytest.fixture
def silent_port():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        yield str(sock.getsockname()[1])
    finally:
        sock.close()


def test_a_valid_message_exits_0_quietly(served, capsys):
    ctl, port = served
    assert main(["send", "/vibsynth/ch/2/intensity", "0.5", "--port", port]) == 0
    assert capsys.readouterr() == ("", "")
    assert _eventually(lambda: ctl.get("intensity", 1), 0.5) == 0.5


def test_a_refused_value_prints_the_server_error_once_and_exits_1(served, capsys):
    ctl, port = served
    assert main(["send", "/vibsynth/intensity", "2", "--port", port]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert err == "vibsynth: error: /vibsynth/intensity: intensity 2 is outside the allowed range [0, 1]\n"
    assert ctl.get("intensity", 0) == 0.0
    # an unknown address (another prefix): the server's error about it, not about send's own /ping
    assert main(["send", "/other/intensity", "0.5", "--port", port]) == 1
    assert capsys.readouterr().err == "vibsynth: error: /other/intensity: unknown address\n"


def test_wait_reply_prints_replies_not_the_barrier(served, capsys):
    ctl, port = served
    assert main(["send", "/vibsynth/ch/2/intensity", "0.25", "--port", port]) == 0
    assert main(["send", "/vibsynth/ch/2/get", "intensity", "--port", port, "--wait-reply", "5"]) == 0
    assert capsys.readouterr() == ("/vibsynth/ch/2/intensity f 0.25\n", "")
    assert main(["send", "/vibsynth/ping", "x", "3", "--types", "Sc", "--port", port, "--wait-reply", "5"]) == 0
    assert capsys.readouterr().out == "/vibsynth/pong Sc x 3\n"
    assert main(["send", "/vibsynth/intensity", "2", "--port", port, "--wait-reply", "5"]) == 1
    out, err = capsys.readouterr()
    assert out == "/vibsynth/error ss /vibsynth/intensity 'intensity 2 is outside the allowed range [0, 1]'\n"
    assert err == ""  # printed once


def test_wait_reply_with_no_server_times_out_with_one_line(silent_port, capsys):
    started = time.monotonic()
    assert main(["send", "/vibsynth/status", "--port", silent_port, "--wait-reply", "0.3"]) == 1
    assert time.monotonic() - started >= 0.3
    assert capsys.readouterr() == ("", f"vibsynth: error: no reply from 127.0.0.1:{silent_port} within 0.3 s\n")


def test_without_wait_reply_a_silent_port_is_not_an_error(silent_port, capsys):
    assert main(["send", "/vibsynth/intensity", "0.5", "--port", silent_port]) == 0
    assert capsys.readouterr() == ("", "")


def _eventually(read, want, timeout: float = 5.0):
    """``read()`` once it equals ``want`` (or its last value after ``timeout``).

    send's /ping reply can leave the server before the end of the receive batch that held the
    knob move (immediate moves are coalesced and handed over at the batch's end): the state is
    checked as it settles, not at the instant send returns.
    """
    deadline = time.monotonic() + timeout
    while (value := read()) != want and time.monotonic() < deadline:
        time.sleep(0.01)
    return value


def test_delay_sends_a_bundle(served):
    ctl, port = served
    assert main(["send", "/vibsynth/intensity", "0.25", "--delay", "0", "--port", port]) == 0
    assert _eventually(lambda: ctl.get("intensity", 0), 0.25) == 0.25
    assert main(["send", "/vibsynth/intensity", "0.5", "--delay", "0.05", "--port", port]) == 0
    assert _eventually(lambda: ctl.get("intensity", 0), 0.5) == 0.5  # a target at once, applied at its frame


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--wait-reply", "nan"], "--wait-reply must be a finite number of seconds >= 0, got nan"),
        (["--wait-reply", "-1"], "--wait-reply must be a finite number of seconds >= 0, got -1"),
        (["--from-port", "99999"], "--from-port 99999 is outside [0, 65535] (0 = any)"),
        (["--port", "0"], "--port 0 is outside [1, 65535]"),
        (["--delay", "inf"], "--delay must be finite"),
        (["--types", "ff"], "--types 'ff' needs 2 value(s), got 1"),
    ],
)
def test_bad_options_give_one_line_and_exit_2(extra, message, capsys):
    assert main(["send", "/vibsynth/intensity", "0.5", *extra]) == 2
    assert capsys.readouterr() == ("", f"vibsynth: error: {message}\n")


def test_no_traceback_from_the_console_script():
    for extra in (["--wait-reply", "nan"], ["--from-port", "99999"]):
        run = subprocess.run(
            [sys.executable, "-m", "vibsynth", "send", "/vibsynth/intensity", "0.5", *extra],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert run.returncode == 2
        assert run.stderr.count("\n") == 1 and run.stderr.startswith("vibsynth: error: ")
        assert "Traceback" not in run.stderr


def test_prefix_of():
    assert prefix_of("/vibsynth/ch/2/intensity") == "/vibsynth"
    assert prefix_of("/vibsynth/ch/*/balance") == "/vibsynth"
    assert prefix_of("/vibsynth/source/3/pos") == "/vibsynth"
    assert prefix_of("/haptics/source/*/get") == "/haptics"
    assert prefix_of("/vibsynth/status") == "/vibsynth"
    assert prefix_of("/haptics/texture") == "/haptics"
    assert prefix_of("/intensity") == ""
