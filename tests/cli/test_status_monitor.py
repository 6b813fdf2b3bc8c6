"""``vibsynth status`` and ``vibsynth monitor`` against a real OSC server in this process."""

from __future__ import annotations

import json
import queue
import socket
import threading
import time

import pytest

from tests.control.osc.delivered import wait_delivered
from tests.control.osc.fakes import make_controller
from tests.e2e.oscclient import free_udp_port
from tests.e2e.test_osc_e2e import OscDump, oscsend, require_tools
from vibsynth.cli import main
from vibsynth.control.controller import Controller
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.server import OscServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis


@pytest.fixture
def server():
    ctl = make_controller(2)
    srv = OscServer(ctl, port=0)
    srv.start()
    yield srv, ctl
    srv.stop()


@pytest.fixture
def engine_server():
    """A 2-channel server in front of a real engine: its compiled fast path takes knob messages."""
    engine = Engine(
        build_bank(default_basis(), BankSpec(fs=8000.0, loop_seconds=1.0, levels=5)), channels=2, max_block=256
    )
    srv = OscServer(Controller(engine), port=0)
    srv.start()
    yield srv
    srv.stop()


def _start_monitor(srv: OscServer, count: int) -> tuple[threading.Thread, dict]:
    """``vibsynth monitor --count N`` in a thread, returned once it has subscribed."""
    result: dict = {}
    thread = threading.Thread(
        target=lambda: result.update(
            code=main(
                ["monitor", "--host", "127.0.0.1", "--port", str(srv.port), "--count", str(count), "--seconds", "20"]
            )
        )
    )
    thread.start()
    deadline = time.monotonic() + 5
    while not len(srv.monitor) and time.monotonic() < deadline:
        time.sleep(0.01)
    wait_delivered(srv)  # the subscription's handler has returned: the next knob messages go the fast way
    return thread, result


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
    thread, result = _start_monitor(srv, 2)
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


#: What oscsend sends (address, types, arguments): knob moves the fast path takes, then one
#: message for the handler. The first, global, moves both channels of the server.
SENT = [
    ("/vibsynth/intensity", "f", "0.3"),
    ("/vibsynth/ch/2/texture", "ff", "0.25", "-1.5"),
    ("/vibsynth/balance", "d", "0.75"),
    ("/vibsynth/ch/1/intensity", "i", "1"),
    ("/vibsynth/ch/1/get", "s", "balance"),
]


def _as_received(text: str) -> tuple:
    """``/a ff 0.25 -1.5`` -> ("/a", "ff", 0.25, -1.5): numbers by value (oscdump prints %f, we %g)."""
    address, types, *args = text.split()
    return (address, types, *(round(float(a), 5) if tag in "ifdh" else a for tag, a in zip(types, args, strict=True)))


def test_monitor_prints_fast_path_messages_as_sent_like_oscdump(engine_server, capsys):
    require_tools("oscsend", "oscdump")
    dump_port = free_udp_port()
    dump = OscDump(dump_port)
    try:
        deadline = time.monotonic() + 10
        while True:  # until oscdump listens
            oscsend(dump_port, "/ready")
            try:
                dump.wait_for("/ready", timeout=0.2)
                break
            except AssertionError:
                assert time.monotonic() < deadline, "oscdump did not start"
        thread, result = _start_monitor(engine_server, len(SENT))
        for message in SENT:  # the same packets to the server and to oscdump
            oscsend(engine_server.port, *message)
            oscsend(dump_port, *message)
        thread.join(timeout=20)
        dumped = []
        for _ in SENT:
            try:
                dumped.append(dump.lines.get(timeout=10))
            except queue.Empty:
                break
    finally:
        dump.close()
    assert result == {"code": 0}
    lines = capsys.readouterr().out.splitlines()
    sources = [line.split()[1] for line in lines]
    assert sources == ["osc-fast"] * 4 + ["osc"]  # one line per message, the global one too
    shown = [line.split(maxsplit=2)[2] for line in lines]
    assert all(text.endswith(")") and "  (udp 127.0.0.1:" in text for text in shown)
    monitored = [_as_received(text.rsplit("  (", 1)[0]) for text in shown]
    assert monitored == [_as_received(line) for line in dumped]
    assert monitored[0][:2] == ("/vibsynth/intensity", "f") and engine_server.counters()["fast_path"] == 4
