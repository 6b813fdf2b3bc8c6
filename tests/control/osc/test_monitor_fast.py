"""What the compiled fast path tells monitors: each datagram it took, as received, only while watched.

The receive loop (``_fast.Receiver``) runs on a real socket in front of a real engine core; its
``on_state`` callback is the test's, so what it hands over is seen directly.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from vibsynth.control.osc import _fast
from vibsynth.control.osc.address import AddressSpace
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.fast import fast_table
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis

#: Fast-path datagrams the loop keeps between two hand-overs (``MAX_SEEN`` in ``_fast.c``).
MAX_SEEN = 256


class Loop:
    """A receive loop on a UDP socket; records every ``on_state`` and ``on_slow`` call."""

    def __init__(self, channels: int = 2) -> None:
        engine = Engine(
            build_bank(default_basis(), BankSpec(fs=8000.0, loop_seconds=1.0, levels=5)),
            channels=channels,
            max_block=256,
        )
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.flag = bytearray(1)
        self.seen: list[list[tuple[bytes, tuple[str, int], float]]] = []
        self.updates: list[tuple[str, int, float]] = []
        self.slow: list[bytes] = []
        self.receiver = _fast.Receiver(
            self.sock.fileno(),
            engine._core,
            fast_table(AddressSpace("/vibsynth", channels)),
            -3.0,
            3.0,
            lambda items: self.slow.extend(data for data, _ in items),
            self._on_state,
            None,
            self.flag,
        )
        self.thread: threading.Thread | None = None
        self.delivery: threading.Thread | None = None

    def _on_state(self, updates, last_seq, seen) -> None:
        self.updates += updates
        if seen:
            self.seen.append(seen)

    def start(self, deliver: bool = True) -> None:
        """The receive loop and (unless ``deliver`` is False: :meth:`start_delivery` later) its hand-over."""
        self.thread = threading.Thread(target=self.receiver.run, daemon=True)
        self.thread.start()
        if deliver:
            self.start_delivery()

    def start_delivery(self) -> None:
        self.delivery = threading.Thread(target=self._deliver, daemon=True)
        self.delivery.start()

    def _deliver(self) -> None:
        while self.receiver.deliver(0.1):
            pass

    def wait_fast(self, count: int) -> None:
        """Until the loop has taken ``count`` datagrams on the fast path (or 10 s)."""
        deadline = time.monotonic() + 10.0
        while self.receiver.counters()["fast"] < count and time.monotonic() < deadline:
            time.sleep(0.005)

    def stop(self) -> None:
        self.receiver.stop()
        assert self.thread is not None
        self.thread.join(timeout=5)
        assert self.delivery is not None
        self.delivery.join(timeout=5)  # deliver() hands over what run() queued before it says False
        self.sock.close()


@pytest.fixture
def loop():
    loop = Loop()
    yield loop
    if loop.thread is not None and loop.thread.is_alive():
        loop.stop()


def _send_all(port: int, packets: list[bytes]) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.bind(("127.0.0.1", 0))
        for data in packets:
            sender.sendto(data, ("127.0.0.1", port))
        return sender.getsockname()[1]


def test_a_watched_loop_hands_over_each_datagram_as_received_with_sender_and_arrival(loop):
    packets = [
        encode_message("/vibsynth/intensity", (0.3,), "f"),  # global: moves both channels, one datagram
        encode_message("/vibsynth/ch/2/texture", (0.25, -1), "fi"),
        encode_message("/vibsynth/ch/1/balance", (1.5,), "d"),
    ]
    loop.flag[0] = 1
    loop.start()
    before = time.time()
    port = _send_all(loop.port, packets)
    loop.wait_fast(3)
    after = time.time()
    loop.stop()
    assert loop.receiver.counters()["fast"] == 3 and loop.slow == []
    seen = [item for chunk in loop.seen for item in chunk]
    assert [data for data, _, _ in seen] == packets
    assert {address for _, address, _ in seen} == {("127.0.0.1", port)}
    times = [when for _, _, when in seen]
    assert before <= times[0] <= times[1] <= times[2] <= after
    # the controller still learns the knobs of each channel (latest values)
    last = {(name, channel): value for name, channel, value in loop.updates}
    assert last == pytest.approx(
        {("intensity", 0): 0.3, ("intensity", 1): 0.25, ("balance", 0): 1.5, ("balance", 1): -1.0}
    )


def test_an_unwatched_loop_keeps_nothing(loop):
    loop.start()
    _send_all(loop.port, [encode_message("/vibsynth/ch/1/intensity", (0.5,), "f")] * 10)
    loop.wait_fast(10)
    loop.flag[0] = 1  # a monitor arrives: later datagrams only
    _send_all(loop.port, [encode_message("/vibsynth/ch/2/intensity", (0.25,), "f")])
    loop.wait_fast(11)
    loop.stop()
    assert loop.receiver.counters()["fast"] == 11
    assert [[data for data, _, _ in chunk] for chunk in loop.seen] == [
        [encode_message("/vibsynth/ch/2/intensity", (0.25,), "f")]
    ]


def test_more_datagrams_than_the_log_holds_are_all_handed_over_in_order(loop):
    """While the monitors' log is full (Python has not taken it yet), datagrams go Python's way."""
    values = np.random.default_rng(26).uniform(0, 1, MAX_SEEN + 44).astype(np.float32)
    packets = [encode_message("/vibsynth/ch/1/intensity", (float(v),), "f") for v in values]
    loop.flag[0] = 1
    loop.start(deliver=False)  # nothing takes the log: it fills up
    _send_all(loop.port, packets)
    deadline = time.monotonic() + 10.0
    while loop.receiver.counters()["packets"] < len(packets) and time.monotonic() < deadline:
        time.sleep(0.005)
    loop.start_delivery()
    loop.stop()
    counters = loop.receiver.counters()
    assert (counters["fast"], counters["slow"], counters["queue_full"]) == (MAX_SEEN, 44, 0)
    assert [len(chunk) for chunk in loop.seen] == [MAX_SEEN]
    assert [data for chunk in loop.seen for data, _, _ in chunk] + loop.slow == packets


def test_the_watch_buffer_must_hold_a_byte():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        with pytest.raises(ValueError, match="watch"):
            _fast.Receiver(sock.fileno(), None, [], 0.0, 0.0, print, print, None, bytearray(0))
        with pytest.raises(TypeError):
            _fast.Receiver(sock.fileno(), None, [], 0.0, 0.0, print, print, None, "1")
