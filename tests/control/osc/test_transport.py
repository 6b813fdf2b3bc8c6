"""TCP framing: SLIP (OSC 1.1) and length prefixes (OSC 1.0, liblo), told apart per connection."""

from __future__ import annotations

import os
import socket
import threading
import time

import numpy as np
import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.control.osc.codec import decode_packet, encode_message
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.transport import (
    RECEIVE_PRIORITY,
    FramingDetector,
    LengthPrefixDecoder,
    SlipDecoder,
    UdpTransport,
    length_encode,
    slip_encode,
)


def _packets(rng: np.random.Generator, n: int) -> list[bytes]:
    """Random packets, including every byte value (so SLIP's END/ESC appear inside)."""
    return [rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes() for _ in range(n)]


def _chunks(rng: np.random.Generator, data: bytes) -> list[bytes]:
    cuts = np.sort(rng.choice(np.arange(1, len(data)), size=min(40, len(data) - 1), replace=False))
    return [data[a:b] for a, b in zip([0, *cuts.tolist()], [*cuts.tolist(), len(data)])]


@pytest.mark.parametrize("seed", range(5))
def test_length_prefixed_stream_cut_anywhere_gives_back_every_packet(seed):
    rng = np.random.default_rng(seed)
    packets = _packets(rng, 30)
    decoder = LengthPrefixDecoder()
    out = [frame for chunk in _chunks(rng, b"".join(map(length_encode, packets))) for frame in decoder.feed(chunk)]
    assert out == packets and not decoder.pending and decoder.oversized == 0


def test_an_oversized_length_is_skipped_without_storing_it():
    decoder = LengthPrefixDecoder(max_frame=100)
    after = encode_message("/vibsynth/ping", (1,))
    frames = decoder.feed((1000).to_bytes(4, "big") + b"x" * 400)
    assert frames == [] and decoder.oversized == 1 and decoder.pending
    assert len(decoder._buf) < 8  # the 400 bytes were counted off, not kept
    frames = decoder.feed(b"x" * 600 + length_encode(after))
    assert frames == [after] and not decoder.pending


def test_a_4_gb_announcement_costs_no_memory():
    decoder = LengthPrefixDecoder()
    decoder.feed(b"\xff\xff\xff\xff" + b"y" * 65536)
    assert decoder.oversized == 1 and len(decoder._buf) == 0 and decoder._skip == 0xFFFFFFFF - 65536


@pytest.mark.parametrize(
    "first, framing",
    [(b"\xc0", "slip"), (b"/", "slip"), (b"#", "slip"), (b"\x00", "length"), (b"\x7f", "length")],
)
def test_the_first_byte_tells_the_framing(first, framing):
    detector = FramingDetector()
    assert detector.framing is None and detector.encode is slip_encode
    detector.feed(first)
    assert detector.framing == framing
    assert detector.encode is (slip_encode if framing == "slip" else length_encode)


@pytest.mark.parametrize("seed", range(3))
def test_detector_decodes_both_framings_of_real_messages(seed):
    rng = np.random.default_rng(seed)
    messages = [encode_message("/vibsynth/ch/1/intensity", (float(v),)) for v in rng.random(20)]
    for encode, decoder_type in ((slip_encode, SlipDecoder), (length_encode, LengthPrefixDecoder)):
        detector = FramingDetector()
        stream = b"".join(map(encode, messages))
        out = [frame for chunk in _chunks(rng, stream) for frame in detector.feed(chunk)]
        assert out == messages and isinstance(detector._decoder, decoder_type)


def _request(conn: socket.socket, packet: bytes, decoder) -> bytes:
    conn.sendall(packet)
    conn.settimeout(5.0)
    while True:
        chunk = conn.recv(65536)
        assert chunk, "the server closed the connection"
        frames = decoder.feed(chunk)
        if frames:
            return frames[0]


@pytest.mark.parametrize("framing", ["slip", "length"])
def test_server_answers_each_connection_in_its_own_framing(framing):
    ctl = make_controller(1)
    server = OscServer(ctl, port=0, tcp=True)
    server.start()
    encode, decoder = (slip_encode, SlipDecoder()) if framing == "slip" else (length_encode, LengthPrefixDecoder())
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=5.0) as conn:
            conn.sendall(encode(encode_message("/vibsynth/intensity", (0.25,))))
            reply = _request(conn, encode(encode_message("/vibsynth/ping", (7,))), decoder)
            assert decode_packet(reply).address == "/vibsynth/pong"
            assert ctl.get("intensity", 0) == 0.25
            reply = _request(conn, encode(encode_message("/vibsynth/ch/2/intensity", (0.5,))), decoder)
            msg = decode_packet(reply)
            assert msg.address == "/vibsynth/error" and "channel 2 out of range" in msg.args[1]
    finally:
        server.stop()


# ---------------------------------------------------------------------- the UDP receive thread's scheduling
def _fifo_allowed() -> bool:
    """Whether this process may put a thread under SCHED_FIFO (root, CAP_SYS_NICE or RLIMIT_RTPRIO)."""
    if not hasattr(os, "sched_setscheduler"):
        return False
    result = []

    def probe() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            result.append(True)
        except OSError:
            result.append(False)

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    return result[0]


needs_fifo = pytest.mark.skipif(not _fifo_allowed(), reason="SCHED_FIFO not allowed here")


class _Batches:
    """on_batch for a bare UdpTransport: records each batch's data and the thread's policy then."""

    def __init__(self) -> None:
        self.data: list[bytes] = []
        self.policies: list[int] = []
        self.event = threading.Event()

    def __call__(self, batch: list) -> None:
        self.policies.append(os.sched_getscheduler(0))
        self.data.extend(data for data, _peer in batch)
        self.event.set()


def _send_and_wait(udp: UdpTransport, batches: _Batches, data: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(data, ("127.0.0.1", udp.port))
    assert batches.event.wait(5.0), "the datagram never reached the handler"
    batches.event.clear()


def _policy_of(udp: UdpTransport) -> tuple[int, int]:
    assert udp._thread is not None and udp._thread.native_id is not None
    tid = udp._thread.native_id
    return os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority


def _wait_policy(udp: UdpTransport, policy: int) -> tuple[int, int]:
    deadline = time.monotonic() + 5.0
    while _policy_of(udp)[0] != policy and time.monotonic() < deadline:
        time.sleep(0.005)
    return _policy_of(udp)


@needs_fifo
def test_the_receive_loop_waits_under_real_time_scheduling_and_python_runs_normally():
    batches = _Batches()
    udp = UdpTransport("127.0.0.1", 0, batches)
    main_policy = os.sched_getscheduler(0)
    udp.start()
    try:
        assert udp.realtime
        # waiting for a datagram: SCHED_FIFO at the receive priority, this (main) thread unchanged
        assert _policy_of(udp) == (os.SCHED_FIFO, RECEIVE_PRIORITY)
        assert os.sched_getscheduler(0) == main_policy
        message = encode_message("/vibsynth/ping", [7])
        _send_and_wait(udp, batches, message)
        assert batches.data == [message]
        # the Python handler ran normally scheduled, and the loop is real-time again afterwards
        assert batches.policies == [os.SCHED_OTHER]
        assert _wait_policy(udp, os.SCHED_FIFO) == (os.SCHED_FIFO, RECEIVE_PRIORITY)
        _send_and_wait(udp, batches, message)
        assert batches.policies == [os.SCHED_OTHER, os.SCHED_OTHER] and len(batches.data) == 2
    finally:
        udp.stop()


def test_priority_0_keeps_the_receive_loop_normally_scheduled():
    batches = _Batches()
    udp = UdpTransport("127.0.0.1", 0, batches, priority=0)
    udp.start()
    try:
        assert not udp.realtime
        assert _policy_of(udp)[0] == os.SCHED_OTHER
        _send_and_wait(udp, batches, b"/x\0\0,\0\0\0")
        assert batches.data == [b"/x\0\0,\0\0\0"] and batches.policies == [os.SCHED_OTHER]
    finally:
        udp.stop()


def test_a_refused_real_time_priority_leaves_a_working_normally_scheduled_loop(monkeypatch):
    def refuse(pid, policy, param):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    batches = _Batches()
    udp = UdpTransport("127.0.0.1", 0, batches)
    udp.start()
    try:
        assert not udp.realtime
        assert _policy_of(udp)[0] == os.SCHED_OTHER
        _send_and_wait(udp, batches, b"/x\0\0,\0\0\0")
        assert batches.data == [b"/x\0\0,\0\0\0"]
    finally:
        udp.stop()


@needs_fifo
def test_the_server_banner_says_the_receive_thread_is_real_time():
    server = OscServer(make_controller(), port=0)
    server.start()
    try:
        assert server.udp.realtime
        assert f"real-time receive thread (SCHED_FIFO {RECEIVE_PRIORITY})" in server.describe()
    finally:
        server.stop()


def test_osc_receive_priority_setting_reaches_the_receive_loop():
    """``osc.receive_priority: 0`` (the setting) gives a normally scheduled receive loop; 9 is the highest."""
    import argparse

    from vibsynth.control.osc.adapter import create
    from vibsynth.errors import ConfigError
    from vibsynth.settings.config import load_config

    settings = load_config(overrides={"osc": {"port": 0, "receive_priority": 0}}).settings
    server = create(settings, argparse.Namespace(), make_controller())
    assert server is not None
    server.start()
    try:
        assert server.udp.priority == 0 and not server.udp.realtime
        assert "real-time receive thread" not in server.describe()
    finally:
        server.stop()
    assert load_config(overrides={"osc": {"receive_priority": 9}}).settings.osc.receive_priority == 9
    with pytest.raises(ConfigError, match="receive_priority"):
        load_config(overrides={"osc": {"receive_priority": 10}})


def test_a_receive_loop_that_fails_is_logged_once_and_counted(caplog):
    """The compiled loop ends with OSError on a descriptor that is not a socket (a persistent error,
    not one bad datagram): the transport says so in one line, counts it, and its thread ends."""
    import logging

    from vibsynth.control.osc.fast import make_receiver

    read_fd, write_fd = os.pipe()
    os.write(write_fd, b"x")  # readable: the loop's recvfrom meets ENOTSOCK
    try:
        udp = UdpTransport(
            "127.0.0.1",
            0,
            _Batches(),
            receiver_factory=lambda fd, on_slow, allow: make_receiver(read_fd, on_slow, allow),
        )
        with caplog.at_level(logging.ERROR, logger="vibsynth.control.osc"):
            udp.start()
            assert udp._thread is not None
            udp._thread.join(timeout=10)
            assert not udp._thread.is_alive()
        udp.stop()
        assert udp.stats.receive_failed == 1
        lines = [r.getMessage() for r in caplog.records if "receive loop" in r.getMessage()]
        assert len(lines) == 1 and f"port {udp.port} stopped" in lines[0], lines
    finally:
        os.close(read_fd)
        os.close(write_fd)
