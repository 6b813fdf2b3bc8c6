"""The compiled OSC receive loop (``vibsynth/control/osc/_fast.c``) called the wrong way from
Python: every call raises TypeError, ValueError, RuntimeError or OSError naming what was wrong.

Issue 31, findings 3 and 4: ``core`` was cast to a Core whatever it was; ``__init__`` on a running
receiver freed what the receive thread used; ``run()`` retried any receive error forever (a
descriptor that is not a socket spun at 100 % CPU and ignored ``stop()``). ``scripts/sanitize.sh``
runs this file against ASan/UBSan builds. What could hang or crash runs in a child process.
"""

from __future__ import annotations

import errno
import socket
import sys
import threading
import time

import numpy as np
import pytest

from tests.isolated import run_python
from vibsynth.control.osc import _fast
from vibsynth.engine import _core
from vibsynth.engine._input import InputRing


def receiver(fd: int, core: object = None, table: list[tuple[bytes, int, int]] | None = None) -> _fast.Receiver:
    return _fast.Receiver(fd, core, table or [], -3.0, 3.0, print, print, None)  # type: ignore[arg-type]


@pytest.fixture
def udp():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    yield sock
    sock.close()


NOT_CORES = {
    "object": object(),
    "an array": np.zeros(1 << 16, np.uint8),
    "bytes": b"\0" * 4096,
    "an input ring": InputRing(1, 4, 1000.0),
    "the Core type": _core.Core,
}


@pytest.mark.parametrize("core", NOT_CORES.values(), ids=NOT_CORES.keys())
def test_a_core_that_is_not_a_core_is_a_type_error(udp, core):
    with pytest.raises(TypeError, match="core must be a vibsynth.engine._core.Core or None, not "):
        receiver(udp.fileno(), core, [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1)])


def test_an_uninitialised_core_is_refused(udp):
    with pytest.raises(RuntimeError, match="core: the Core is not initialised"):
        receiver(udp.fileno(), _core.Core.__new__(_core.Core), [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1)])


@pytest.mark.parametrize(
    ("args", "error", "message"),
    [
        ((-1, None, [], -3.0, 3.0, print, print, None), ValueError, "fd must be a socket descriptor"),
        ((1 << 40, None, [], -3.0, 3.0, print, print, None), ValueError, "fd must be a socket descriptor"),
        ((0, None, [], -3.0, 3.0, None, print, None), TypeError, "on_slow and on_state must be callable"),
        ((0, None, [], -3.0, 3.0, print, 3, None), TypeError, "on_slow and on_state must be callable"),
        ((0, None, [(b"/x", 1, -1)], -3.0, 3.0, print, print, None), ValueError, "fast-path table"),
    ],
    ids=["fd -1", "fd 2**40", "on_slow None", "on_state 3", "a table without a core"],
)
def test_bad_arguments_raise(args, error, message):
    with pytest.raises(error, match=message):
        _fast.Receiver(*args)


def test_a_table_channel_below_minus_one_is_refused(udp):
    core = _core.Core(**_core_args())
    with pytest.raises(ValueError, match="fast-path table"):
        receiver(udp.fileno(), core, [(b"/vibsynth/ch/x/intensity", _fast.M_INTENSITY, -2)])
    receiver(udp.fileno(), core, [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1)])


def _core_args() -> dict[str, object]:
    signals = np.random.default_rng(3).uniform(-0.5, 0.5, (3, 256)).astype(np.float32)
    peaks = np.abs(signals).max(axis=1).astype(np.float64)
    return dict(
        signals=signals,
        peaks=peaks,
        balances_lo=-3.0,
        balances_hi=3.0,
        offsets=[0, 5],
        fs=1000.0,
        ceiling_db=0.0,
        range_db=40.0,
        glide_s=0.0,
        mute_fade_s=0.0,
        limiter_ceiling=0.9,
        initial_intensity=0.0,
        initial_balance=0.0,
        max_block=64,
        ring_capacity=64,
        schedule_capacity=8,
    )


@pytest.mark.parametrize("call", ["run", "stop", "counters", "deliver"])
def test_an_uninitialised_receiver_refuses_every_method(call):
    rx = _fast.Receiver.__new__(_fast.Receiver)
    with pytest.raises(RuntimeError, match="Receiver is not initialised"):
        getattr(rx, call)(*([0.0] if call == "deliver" else []))


@pytest.mark.parametrize("timeout", [float("nan"), float("inf"), -0.5, 3601.0, 1e300])
def test_deliver_refuses_a_timeout_outside_0_to_3600_s(udp, timeout):
    with pytest.raises(ValueError, match="timeout must be 0..3600 s"):
        receiver(udp.fileno()).deliver(timeout)


def test_deliver_refuses_a_timeout_that_is_not_a_number(udp):
    with pytest.raises(TypeError):
        receiver(udp.fileno()).deliver("1")  # type: ignore[arg-type]


def test_a_second_deliver_at_once_is_refused_and_deliver_ends_when_run_has(udp):
    rx = receiver(udp.fileno())
    results: list[object] = []
    waiting = threading.Thread(target=lambda: results.append(rx.deliver(30.0)), daemon=True)
    waiting.start()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:  # until the first deliver() is inside
        try:
            rx.deliver(0.0)
        except RuntimeError as exc:
            assert "already running" in str(exc)
            break
        time.sleep(0.001)
    else:
        pytest.fail("a second deliver() at once was not refused")
    running = threading.Thread(target=rx.run, daemon=True)
    running.start()
    rx.stop()  # run() returns and wakes deliver(): nothing is left, so it says False at once
    running.join(5.0)
    waiting.join(5.0)
    assert results == [False]
    assert rx.deliver(0.0) is False


def test_a_second_init_is_refused(udp):
    rx = receiver(udp.fileno())
    with pytest.raises(RuntimeError, match="Receiver is already initialised"):
        rx.__init__(udp.fileno(), None, [], -3.0, 3.0, print, print, None)  # type: ignore[misc]
    with pytest.raises(RuntimeError, match="Receiver is already initialised"):
        rx.__init__(-1, object(), [], -3.0, 3.0, print, print, None)  # type: ignore[misc]
    assert rx.counters()["packets"] == 0


def test_init_while_running_is_refused_and_the_loop_goes_on_taking_fast_messages():
    """Finding 3: ``__init__`` on the running receiver cleared what its thread used (a crash)."""
    out = run_python(
        """
        import math, socket, struct, threading, time
        import numpy as np
        from vibsynth.control.osc import _fast
        from vibsynth.engine import _core
        from tests.control.osc.test_fast_hostile import _core_args
        core = _core.Core(**_core_args())
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        table = [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1)]
        rx = _fast.Receiver(sock.fileno(), core, table, -3.0, 3.0, print, lambda *state: None, None)
        thread = threading.Thread(target=rx.run, daemon=True)
        thread.start()
        send = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        def intensity(value):
            send.sendto(b"/vibsynth/intensity\\0,f\\0\\0" + struct.pack(">f", value), sock.getsockname())
        def wait_fast(count):
            deadline = time.monotonic() + 10.0
            while rx.counters()["fast"] < count and time.monotonic() < deadline:
                time.sleep(0.005)
        intensity(0.25)
        wait_fast(1)
        for args in ((sock.fileno(), None, [], 0.0, 1.0, print, print, None),
                     (sock.fileno(), object(), table, 0.0, 1.0, print, print, None)):
            try:
                rx.__init__(*args)
            except RuntimeError as exc:
                print(exc)
        intensity(0.75)
        wait_fast(2)
        rx.stop()
        thread.join(5.0)
        core.render_into(np.zeros((64, 2), np.float32))
        print(thread.is_alive(), rx.counters()["fast"], [k for k, _, _ in core.knob_values()])
        """,
        timeout=60.0,
    )
    assert out.splitlines() == ["Receiver is already initialised (make a new one)"] * 2 + ["False 2 [0.75, 0.75]"]


def test_a_descriptor_that_is_not_a_socket_ends_run_with_an_os_error(tmp_path):
    """Finding 4: a readable non-socket descriptor made run() retry ENOTSOCK forever (stop() ignored)."""
    path = tmp_path / "not-a-socket"
    path.write_bytes(b"x" * 64)
    out = run_python(
        f"""
        import os
        from vibsynth.control.osc import _fast
        fd = os.open({str(path)!r}, os.O_RDONLY)
        rx = _fast.Receiver(fd, None, [], 0.0, 1.0, print, print, None)
        try:
            rx.run()
        except OSError as exc:
            print(exc.errno, rx.counters()["recv_errors"], rx.counters()["packets"])
        """,
        timeout=30.0,
    )
    assert out.split() == [str(errno.ENOTSOCK), "1", "0"]


def test_a_closed_descriptor_ends_run_with_an_os_error():
    out = run_python(
        """
        import os
        from vibsynth.control.osc import _fast
        fd = os.open(os.devnull, os.O_RDONLY)
        os.close(fd)  # nothing opens another file in between: the number stays free
        rx = _fast.Receiver(fd, None, [], 0.0, 1.0, print, print, None)
        try:
            rx.run()
        except OSError as exc:
            print(exc.errno, rx.counters()["recv_errors"])
        """,
        timeout=30.0,
    )
    assert out.split() == [str(errno.EBADF), "1"]


def test_stop_ends_run_on_a_quiet_socket(udp):
    rx = receiver(udp.fileno())
    done: list[object] = []
    thread = threading.Thread(target=lambda: done.append(rx.run()), daemon=True)
    thread.start()
    rx.stop()
    thread.join(10.0)
    assert not thread.is_alive()
    assert done == [None]


@pytest.mark.skipif(sys.platform != "linux", reason="Linux reports ICMP errors to connected UDP sockets")
def test_a_passing_receive_error_is_counted_and_the_loop_goes_on(udp):
    """ECONNREFUSED (an ICMP port unreachable for a datagram sent earlier) is counted, not fatal."""
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    dead = closed.getsockname()
    closed.close()
    udp.connect(dead)
    udp.send(b"nobody listens")
    rx = _fast.Receiver(udp.fileno(), None, [], 0.0, 1.0, lambda items: None, print, None)
    done: list[object] = []
    thread = threading.Thread(target=lambda: done.append(rx.run()), daemon=True)
    thread.start()
    deadline = time.monotonic() + 10.0
    while rx.counters()["recv_errors"] == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert rx.counters()["recv_errors"] == 1
    assert thread.is_alive()  # still receiving
    rx.stop()
    thread.join(10.0)
    assert not thread.is_alive()
    assert done == [None]
    assert rx.counters()["packets"] == 0
