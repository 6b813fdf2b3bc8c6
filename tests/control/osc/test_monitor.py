"""``/vibsynth/monitor``: what the server receives, streamed to subscribers (``vibsynth monitor``)."""

from __future__ import annotations

import socket
import time

import pytest

from tests.control.osc.delivered import wait_delivered
from tests.control.osc.fakes import FakePeer, make_controller
from vibsynth.control.osc.codec import Message, decode_packet, encode_message, iter_messages
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.monitor import LEASE_S, MAX_SUBSCRIBERS, MonitorWorker
from vibsynth.control.osc.server import OscServer
from vibsynth.control.tap import InputTap


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _events(peer: FakePeer) -> list[tuple[str, str]]:
    out = []
    for data in peer.sent:
        packet = decode_packet(data)
        for msg, _ in iter_messages(packet) if not isinstance(packet, Message) else [(packet, None)]:
            if msg.address.endswith("/monitor.event"):
                out.append((msg.args[1], msg.args[2]))
    return out


@pytest.fixture
def rig():
    tap, clock = InputTap(), Clock()
    monitor = MonitorWorker(tap, "/vibsynth", clock=clock)
    handler = OscHandler(make_controller(2), tap=tap, monitor=monitor, sync_worker=None)
    return handler, monitor, clock


def _send(handler, peer, address, *args):
    handler.handle_packet(encode_message(address, args), peer)


def test_subscriber_sees_messages_and_errors_with_their_sender(rig):
    handler, monitor, _ = rig
    watcher, sender = FakePeer(("127.0.0.1", 7000)), FakePeer(("127.0.0.1", 7001))
    _send(handler, watcher, "/vibsynth/monitor", 1)
    assert list(watcher.messages()[-1].args) == ["/vibsynth/monitor", 1]
    _send(handler, sender, "/vibsynth/ch/2/intensity", 0.25)
    _send(handler, sender, "/vibsynth/ch/9/intensity", 0.25)
    monitor.pump()
    events = _events(watcher)
    assert events[0] == ("osc", "/vibsynth/ch/2/intensity f 0.25  (udp 127.0.0.1:7001)")
    assert events[1][0] == "osc" and events[2][0] == "error"
    assert "channel 9 out of range" in events[2][1] and "127.0.0.1:7001" in events[2][1]


def test_lease_expires_unless_renewed_and_unsubscribe_detaches(rig):
    handler, monitor, clock = rig
    peer = FakePeer()
    _send(handler, peer, "/vibsynth/monitor", 1)
    assert handler.tap.active and len(monitor) == 1
    clock.now += LEASE_S - 1
    _send(handler, peer, "/vibsynth/monitor", 1)  # renewed
    clock.now += LEASE_S - 1
    monitor.pump()
    assert len(monitor) == 1
    clock.now += 2
    monitor.pump()
    assert len(monitor) == 0 and not handler.tap.active
    _send(handler, peer, "/vibsynth/monitor", 1)
    _send(handler, peer, "/vibsynth/monitor", 0)
    assert len(monitor) == 0 and not handler.tap.active


def test_off_host_udp_and_too_many_subscribers_are_refused(rig):
    handler, monitor, _ = rig
    remote = FakePeer(("192.0.2.7", 9000))
    remote.datagram = True
    _send(handler, remote, "/vibsynth/monitor", 1)
    assert len(monitor) == 0
    assert "use TCP" in remote.errors()[0][1]
    for k in range(MAX_SUBSCRIBERS):
        _send(handler, FakePeer(("127.0.0.1", 8000 + k)), "/vibsynth/monitor", 1)
    late = FakePeer(("127.0.0.1", 8999))
    _send(handler, late, "/vibsynth/monitor", 1)
    assert "too many monitor subscribers" in late.errors()[0][1]


def test_fast_path_messages_reach_the_monitor_as_sent_through_a_real_server():
    from vibsynth.control.controller import Controller
    from vibsynth.engine.bank import BankSpec, build_bank
    from vibsynth.engine.engine import Engine
    from vibsynth.formats.basis_file import default_basis

    engine = Engine(
        build_bank(default_basis(), BankSpec(fs=8000.0, loop_seconds=1.0, levels=5)), channels=2, max_block=256
    )
    server = OscServer(Controller(engine), port=0)
    server.start()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sender = f"udp 127.0.0.1:{sock.getsockname()[1]}"
    try:
        target = ("127.0.0.1", server.port)
        sock.sendto(encode_message("/vibsynth/monitor", (1,)), target)
        sock.settimeout(5.0)
        assert decode_packet(sock.recv(65536)).address == "/vibsynth/done"  # subscribed
        wait_delivered(server)  # the handler has returned: nothing queues the next datagrams behind it
        # exact knob addresses, not behind a slow-path packet in their batch: the C fast path
        sock.sendto(encode_message("/vibsynth/intensity", (0.5,), "f"), target)  # moves both channels
        sock.sendto(encode_message("/vibsynth/ch/2/texture", (0.25, -1), "fi"), target)
        sock.sendto(encode_message("/vibsynth/ch/1/get", ("balance",), "s"), target)  # the handler's
        seen, deadline = [], time.monotonic() + 10.0
        while time.monotonic() < deadline and len(seen) < 3:
            packet = decode_packet(sock.recv(65536))
            for msg, _ in iter_messages(packet) if not isinstance(packet, Message) else [(packet, None)]:
                if msg.address == "/vibsynth/monitor.event":
                    seen.append((msg.args[1], msg.args[2]))
        assert seen == [
            ("osc-fast", f"/vibsynth/intensity f 0.5  ({sender})"),
            ("osc-fast", f"/vibsynth/ch/2/texture fi 0.25 -1  ({sender})"),
            ("osc", f'/vibsynth/ch/1/get s "balance"  ({sender})'),
        ]
        assert server.counters()["fast_path"] == 2
    finally:
        sock.close()
        server.stop()
