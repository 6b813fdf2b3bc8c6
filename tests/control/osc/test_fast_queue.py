"""The compiled receive loop's queue for Python (``vibsynth/control/osc/_fast.c``): Python never
holds up the socket.

The soak (docs/engine.md, Soak) lost 0.37 % of its OSC messages on a loaded machine: the receive
thread took the GIL to hand datagrams over, waited for it while the interpreter was busy, and the
kernel dropped what overflowed the socket's buffer, without a count. Now run() never takes the
GIL: what is for Python waits in a bounded queue that deliver() hands over on another thread.
The GIL is held on purpose here (a long switch interval and a busy loop), not by the
scheduler's chance.
"""

from __future__ import annotations

import multiprocessing
import socket
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from tests.control.osc.test_fast_hostile import _core_args
from vibsynth.control.osc import _fast
from vibsynth.control.osc.codec import encode_message
from vibsynth.engine import _core

TABLE = [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1)]
SLOW = encode_message("/vibsynth/ping", (), "")  # not a fast-path address: for Python


class Loop:
    """A receiver on a small socket buffer, its receive thread and (optionally) its delivery thread."""

    def __init__(self, rcvbuf: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.core = _core.Core(**_core_args())
        self.slow: list[bytes] = []
        self.states: list[int] = []  # on_state calls: the length of self.slow at each
        self.rx = _fast.Receiver(self.sock.fileno(), self.core, TABLE, -3.0, 3.0, self._on_slow, self._on_state, None)
        self.thread = threading.Thread(target=self.rx.run, daemon=True)
        self.delivery: threading.Thread | None = None

    def _on_slow(self, items: list[tuple[bytes, tuple[str, int]]]) -> None:
        self.slow += [data for data, _ in items]

    def _on_state(self, updates: list, last_seq: int, seen: list) -> None:
        self.states.append(len(self.slow))

    def start_delivery(self) -> None:
        self.delivery = threading.Thread(target=self._deliver, daemon=True)
        self.delivery.start()

    def _deliver(self) -> None:
        while self.rx.deliver(0.1):
            pass

    def wait_packets(self, count: int, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while self.rx.counters()["packets"] < count and time.monotonic() < deadline:
            time.sleep(0.005)

    def stop(self) -> None:
        self.rx.stop()
        self.thread.join(5.0)
        if self.delivery is not None:
            self.delivery.join(5.0)
        self.sock.close()


@pytest.fixture
def make_loop() -> Iterator:
    loops: list[Loop] = []

    def make(rcvbuf: int = 1 << 20) -> Loop:
        loops.append(Loop(rcvbuf))
        return loops[-1]

    yield make
    for loop in loops:
        if loop.thread.is_alive():
            loop.stop()


def _send(port: int, packets: list[bytes], start, done, rate: float) -> None:
    """(a child process) Send ``packets`` at ``rate`` per second once ``start`` is set."""
    while not start.value:
        time.sleep(0.001)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    begin = time.perf_counter()
    for k, data in enumerate(packets):
        sock.sendto(data, ("127.0.0.1", port))
        delay = begin + (k + 1) / rate - time.perf_counter()
        if delay > 0 and k % 16 == 15:
            time.sleep(delay)
    done.value = 1


def _intensities(count: int) -> list[bytes]:
    return [encode_message("/vibsynth/intensity", (k / count,), "f") for k in range(count)]


def test_a_busy_interpreter_loses_no_datagram(make_loop):
    """6,000 datagrams at 5,000/s while this thread holds the GIL: none is lost, all in order.

    The socket's buffer holds about 2,000 of them: a loop that waited for the GIL, as the loop
    before this queue did every 20 ms, loses thousands here.
    """
    loop = make_loop(rcvbuf=1 << 20)
    packets = _intensities(6000)
    marks = (1000, 3000, 5000)
    for k in marks:
        packets[k] = SLOW
    spawn = multiprocessing.get_context("spawn")
    start, done = spawn.RawValue("i", 0), spawn.RawValue("i", 0)
    sender = spawn.Process(target=_send, args=(loop.sock.getsockname()[1], packets, start, done, 5000.0))
    sender.start()
    loop.thread.start()
    loop.start_delivery()
    time.sleep(0.5)  # the sender's interpreter has started
    interval = sys.getswitchinterval()
    sys.setswitchinterval(30.0)  # no other thread gets the GIL until this one blocks
    try:
        start.value = 1
        deadline = time.monotonic() + 20.0
        while not done.value and time.monotonic() < deadline:  # holds the GIL, never blocks
            pass
        held_until_done = bool(done.value)
    finally:
        sys.setswitchinterval(interval)
    sender.join(20.0)
    assert held_until_done, "the sender did not finish within 20 s"
    loop.wait_packets(len(packets))
    loop.stop()
    counters = loop.rx.counters()
    assert counters["packets"] == len(packets)  # the kernel dropped nothing
    assert counters["queue_full"] == 0
    assert counters["fast"] + counters["slow"] == len(packets)
    # what went to Python is, in arrival order, each mark and what came after it while Python waited
    positions = [packets.index(data) if data != SLOW else None for data in loop.slow]
    assert [p for p in positions if p is not None] == sorted(p for p in positions if p is not None)
    assert loop.slow.count(SLOW) == len(marks)
    assert counters["slow"] == len(loop.slow) > len(marks)  # the GIL was held: datagrams queued behind the marks


def test_a_full_queue_drops_and_counts_what_does_not_fit_and_hands_over_the_rest_in_order(make_loop):
    loop = make_loop(rcvbuf=4 << 20)
    loop.thread.start()  # no delivery yet: the queue fills up
    packets = [encode_message("/vibsynth/ping", (k,), "i") for k in range(_fast.QUEUE_MAX + 500)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for k, data in enumerate(packets):
            sender.sendto(data, loop.sock.getsockname())
            if k % 2000 == 1999:
                loop.wait_packets(k + 1 - 2000, timeout=5.0)  # stay within the socket's buffer
    loop.wait_packets(len(packets))
    received = loop.rx.counters()["packets"]
    assert received > _fast.QUEUE_MAX
    counters = loop.rx.counters()
    assert counters["slow"] == _fast.QUEUE_MAX
    assert counters["queue_full"] == received - _fast.QUEUE_MAX
    loop.start_delivery()
    loop.stop()
    assert loop.slow == packets[: _fast.QUEUE_MAX]  # the first ones, in order (the kernel kept order)


def test_fast_moves_wait_behind_a_datagram_for_python(make_loop):
    """Order: while a datagram waits for Python, a fast-path message queues behind it."""
    loop = make_loop()
    loop.thread.start()
    first, second = (
        encode_message("/vibsynth/intensity", (0.25,), "f"),
        encode_message("/vibsynth/intensity", (0.75,), "f"),
    )
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for data in (first, SLOW, second):
            sender.sendto(data, loop.sock.getsockname())
    loop.wait_packets(3)
    counters = loop.rx.counters()
    assert (counters["fast"], counters["slow"]) == (1, 2)
    loop.start_delivery()
    loop.stop()
    assert loop.slow == [SLOW, second]
    assert loop.states == [0]  # the fast move was recorded before Python saw what came after it


def test_what_run_queued_until_it_returned_is_all_handed_over_during_a_flood(make_loop):
    """stop() in the middle of a flood for Python: deliver() says False only after the last of it."""
    loop = make_loop()
    loop.thread.start()
    loop.start_delivery()
    sending = threading.Event()
    sending.set()
    target = loop.sock.getsockname()

    def flood() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            while sending.is_set():
                sender.sendto(SLOW, target)

    thread = threading.Thread(target=flood, daemon=True)
    thread.start()
    loop.wait_packets(2000)
    loop.stop()
    sending.clear()
    thread.join(5.0)
    counters = loop.rx.counters()
    assert counters["slow"] >= 2000 and counters["queue_full"] == 0
    assert counters["delivered"] == counters["slow"] == len(loop.slow)
    assert not loop.thread.is_alive() and loop.delivery is not None and not loop.delivery.is_alive()
