"""``vibsynth status`` and ``vibsynth monitor`` against a real OSC server in this process."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.cli import main
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.server import OscServer


@pytest.fixture
def server():
    ctl = make_controller(2)
    srv = OscServer(ctl, port=0)
    srv.start()
    yield srv, ctl
    srv.stop()


def test_status_table_and_json(server, capsys):
    srv, ctl = server
    ctl.set_texture(0.25, -0.5, channels=[1])
    assert main(["status", "--host", "127.0.0.1", "--port", str(srv.port)]) == 0
    out = capsys.readouterr().out
    assert f"at 127.0.0.1:{srv.port}" in out and "control   messages" in out
    rows = [line.split() for line in out.splitlines() if line.strip()[:1].isdigit()]
    assert rows == [["1", "0.000", "+0.000", "20", "-", "-"], ["2", "0.250", "-0.500", "20", "-", "-"]]
    assert main(["status", "--host", "127.0.0.1", "--port", str(srv.port), "--format", "json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["channels"] == 2 and data["ch2.intensity"] == pytest.approx(0.25)


def test_status_names_the_last_error(server, capsys):
    srv, _ = server
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(encode_message("/vibsynth/ch/7/intensity", (0.5,)), ("127.0.0.1", srv.port))
    time.sleep(0.2)
    assert main(["status", "--host", "127.0.0.1", "--port", str(srv.port)]) == 0
    assert "last error" in capsys.readouterr().out.split("channel 7 out of range")[0]


def test_status_without_a_server_is_one_line(capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    code = main(["status", "--host", "127.0.0.1", "--port", str(port), "--timeout", "0.3"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and err.startswith("vibsynth: error:") and str(port) in err


def test_monitor_prints_what_the_server_receives(server, capsys):
    srv, _ = server
    result = {}
    thread = threading.Thread(
        target=lambda: result.update(
            code=main(["monitor", "--host", "127.0.0.1", "--port", str(srv.port), "--count", "2", "--seconds", "10"])
        )
    )
    thread.start()
    deadline = time.monotonic() + 5
    while not len(srv.monitor) and time.monotonic() < deadline:
        time.sleep(0.01)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(encode_message("/vibsynth/ch/1/balance", (0.5,), "f"), ("127.0.0.1", srv.port))
        sock.sendto(encode_message("/vibsynth/nothing", ()), ("127.0.0.1", srv.port))
    thread.join(timeout=10)
    assert result == {"code": 0}
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    assert lines[0].split(maxsplit=1)[1].startswith("osc      /vibsynth/ch/1/balance f 0.5  (udp 127.0.0.1:")
    assert lines[1].split()[1:3] == ["osc", "/vibsynth/nothing"]
    deadline = time.monotonic() + 5
    while len(srv.monitor) and time.monotonic() < deadline:  # it unsubscribed on the way out
        time.sleep(0.01)
    assert len(srv.monitor) == 0
