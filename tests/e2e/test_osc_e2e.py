"""End to end: the real ``vibsynth serve`` process driven over OSC by liblo's ``oscsend``
(a client no one here wrote), replies received with ``oscdump`` and a socket; a knob set over
OSC is visible in the output captured from JACK; a load test of 10,000 messages/s.

Skips with a clear message when oscsend/oscdump or JACK are missing, unless
``VIBSYNTH_E2E_REQUIRED=1`` (CI), where it fails. Load test duration:
``VIBSYNTH_OSC_LOAD_SECONDS`` (default 10; the issue's figure is 30).

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_osc_e2e.py -q -s``.
"""

from __future__ import annotations

import os
import queue
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.jackutil import REALTIME, assert_no_collapse  # noqa: E402
from tests.e2e.oscclient import OscClient as Client  # noqa: E402
from tests.e2e.oscclient import free_udp_port
from tests.serveutil import stop_serve
from vibsynth.control.osc.codec import decode_packet, encode_bundle, encode_message, unix_to_ntp

pytestmark = pytest.mark.e2e


ROOT = Path(__file__).resolve().parents[2]
REQUIRED = os.environ.get("VIBSYNTH_E2E_REQUIRED") == "1"
LOAD_SECONDS = float(os.environ.get("VIBSYNTH_OSC_LOAD_SECONDS", "10"))
LOAD_RATE = int(os.environ.get("VIBSYNTH_OSC_LOAD_RATE", "10000"))
# Underflows under load are the machine's as much as ours (the dummy driver's late wake-ups count
# too): the tests assert only no collapse (jackutil.assert_no_collapse) and print the count; the
# distributions beside the server alone and the peers are benchmarks/bench_rt_share.py's.
START_TIMEOUT_S = 180.0


def unavailable(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"VIBSYNTH_E2E_REQUIRED=1 but {reason}")
    pytest.skip(reason)


def require_tools(*tools: str) -> None:
    missing = [t for t in tools if shutil.which(t) is None]
    if missing:
        unavailable(f"{', '.join(missing)} not found (Debian package liblo-tools)")


def jack_available() -> bool:
    try:
        from tests.e2e.jackutil import jack_server_available
    except ImportError:
        return False
    return jack_server_available()[0]


def _socket_ready(port: int) -> bool:
    probe = Client(port)
    try:
        probe.request("/vibsynth/ping", 1, expect="/vibsynth/pong", timeout=0.5)
        return True
    except (TimeoutError, ConnectionRefusedError):
        return False
    finally:
        probe.close()


#: What serve prints once every part (OSC, OSCQuery, Follow, VRChat, studio) has started.
STARTED_LINE = "make it vibrate with"


def start_serve(
    tmp_path: Path, *, output: str = "null", extra_config: str = "", env: dict | None = None, ready=_socket_ready
):
    """Start ``vibsynth serve``; return (process, port) once ``ready(port)`` (default: it answers /ping).

    And once serve printed its last start-up line (``make it vibrate with``): the OSC server answers
    before OSCQuery, Follow, VRChat and the studio have started (their /status keys come later).
    """
    port = free_udp_port()
    config = tmp_path / "vibsynth.yaml"
    config.write_text(f"version: 1\nosc:\n  port: {port}\n{extra_config}", encoding="utf-8")
    cmd = [
        sys.executable,
        "-m",
        "vibsynth",
        "serve",
        "--config",
        str(config),
        "--output",
        output,
        "--no-midi",
        "--osc-port",
        str(port),
    ]
    proc_env = dict(os.environ if env is None else env, PYTHONPATH=str(ROOT))
    log = open(tmp_path / "serve.log", "w")
    proc = subprocess.Popen(cmd, cwd=ROOT, env=proc_env, stdout=log, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            raise AssertionError(f"serve exited ({proc.returncode}):\n{(tmp_path / 'serve.log').read_text()}")
        if time.monotonic() > deadline:
            stop_serve(proc)
            raise AssertionError("serve did not answer /ping in time:\n" + (tmp_path / "serve.log").read_text())
        if ready(port) and STARTED_LINE in (tmp_path / "serve.log").read_text():
            return proc, port


def wait_for_stream(status) -> None:
    """Wait until ``status()`` (serve's /status) shows its audio stream running.

    serve answers OSC before its stream runs (a loaded machine opens it later): tests that capture
    its ports or compare its frames and underflows before and after start once it plays.
    """
    deadline = time.monotonic() + START_TIMEOUT_S
    while int(status()["frame"]) <= 0:
        assert time.monotonic() < deadline, "serve's audio stream did not start"
        time.sleep(0.05)


class OscDump:
    """``oscdump -L PORT`` in the background; lines collected in a queue."""

    def __init__(self, port: int) -> None:
        self.proc = subprocess.Popen(
            ["oscdump", "-L", str(port)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
        )
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            head, _, rest = line.strip().partition(" ")
            # oscdump prints the timetag first ("eeabb3d3.0448387d /address types args")
            self.lines.put(rest if "." in head and not head.startswith("/") else line.strip())

    def wait_for(self, prefix: str, timeout: float = 10.0) -> str:
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f"oscdump saw no line starting with {prefix!r}") from None
            if line.startswith(prefix):
                return line

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=10)


def oscsend(port: int, address: str, types: str = "", *args: str) -> None:
    subprocess.run(
        ["oscsend", "127.0.0.1", str(port), address, types, *args]
        if types
        else ["oscsend", "127.0.0.1", str(port), address],
        check=True,
        timeout=10,
    )


# ---------------------------------------------------------------------- null output: protocol
@pytest.fixture(scope="module")
def served(tmp_path_factory):
    require_tools("oscsend", "oscdump")
    tmp = tmp_path_factory.mktemp("osc-e2e")
    dump_port = free_udp_port()
    dump = OscDump(dump_port)

    def ready(port: int) -> bool:  # replies go to oscdump's port
        oscsend(port, "/vibsynth/ping", "i", "7")
        try:
            dump.wait_for("/vibsynth/pong", timeout=0.5)
            return True
        except AssertionError:
            return False

    proc, port = start_serve(tmp, extra_config=f"  reply_port: {dump_port}\n", ready=ready)
    yield port, dump
    stop_serve(proc)
    dump.close()


def test_oscsend_sets_knobs_and_queries_reply_to_oscdump(served):
    port, dump = served
    oscsend(port, "/vibsynth/ch/1/intensity", "f", "0.5")
    oscsend(port, "/vibsynth/balance", "f", "-1.25")
    oscsend(port, "/vibsynth/get", "s", "intensity")
    assert dump.wait_for("/vibsynth/intensity") == "/vibsynth/intensity f 0.500000"
    oscsend(port, "/vibsynth/get", "s", "balance")
    assert dump.wait_for("/vibsynth/balance") == "/vibsynth/balance f -1.250000"
    oscsend(port, "/vibsynth/sync", "i", "42")
    assert dump.wait_for("/vibsynth/synced") == "/vibsynth/synced i 42"


def test_errors_reach_the_sender(served):
    port, dump = served
    oscsend(port, "/vibsynth/intensity", "f", "2.5")
    line = dump.wait_for("/vibsynth/error")
    assert '"/vibsynth/intensity"' in line and "outside the allowed range" in line
    oscsend(port, "/vibsynth/nothing")
    assert '"/vibsynth/nothing" "unknown address"' in dump.wait_for("/vibsynth/error")
    oscsend(port, "/vibsynth/get", "s", "intensity")
    assert dump.wait_for("/vibsynth/intensity") == "/vibsynth/intensity f 0.500000"  # unchanged


def test_status_and_patterns(served):
    port, dump = served
    oscsend(port, "/vibsynth/ch/[1-9]/mute", "i", "1")
    oscsend(port, "/vibsynth/get", "s", "mute")
    assert dump.wait_for("/vibsynth/mute") == "/vibsynth/mute i 1"
    oscsend(port, "/vibsynth/mute", "i", "0")
    oscsend(port, "/vibsynth/status")
    line = dump.wait_for("/vibsynth/status.reply")
    assert '"channels" 1' in line and '"rate" 48000' in line and '"errors"' in line


def test_future_bundle_is_applied_on_time(served):
    port, dump = served
    oscsend(port, "/vibsynth/intensity", "f", "0.1")
    client = Client(port)
    try:
        bundle = encode_bundle(unix_to_ntp(time.time() + 1.0), [encode_message("/vibsynth/intensity", (0.7,), "f")])
        client.sock.sendto(bundle, client.target)
        far = encode_bundle(unix_to_ntp(time.time() + 3600.0), [encode_message("/vibsynth/intensity", (0.9,), "f")])
        client.sock.sendto(far, client.target)
        assert "horizon" in dump.wait_for("/vibsynth/error")
    finally:
        client.close()


# ---------------------------------------------------------------------- JACK: rendered output, load
@pytest.fixture
def jack_serve(tmp_path):
    require_tools("oscsend")
    if not jack_available():
        unavailable("no JACK server reachable (run under scripts/with_jack.sh) or JACK-Client missing")
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    proc, port = start_serve(tmp_path, output="sounddevice", env=env)
    probe = Client(port)
    try:
        wait_for_stream(probe.status)
    finally:
        probe.close()
    yield port
    stop_serve(proc)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x.astype(np.float64)))))


@REALTIME
def test_knob_set_over_osc_is_visible_in_jack_output(jack_serve):
    from tests.e2e.jackutil import JackCapture, portaudio_output_ports

    port = jack_serve
    with JackCapture(0.5) as cap:
        sources = portaudio_output_ports(cap.client)
        assert sources, "serve registered no PortAudio output port in JACK"
        cap.connect(sources[:1])
        cap.arm()
        assert cap.wait()
        silent = _rms(cap.data[:, 0])
    oscsend(port, "/vibsynth/texture", "ff", "0.8", "0.0")
    time.sleep(0.3)  # let the 20 ms glide finish
    with JackCapture(0.5) as cap:
        cap.connect(portaudio_output_ports(cap.client)[:1])
        cap.arm()
        assert cap.wait()
        loud = _rms(cap.data[:, 0])
    print(f"\nRMS before {silent:.2e}, after /texture 0.8 0: {loud:.2e}")
    assert silent < 1e-6 and loud > 1e-3


def _wall_and_frame(cap) -> tuple[float, int]:
    """``time.time()`` and the JACK frame clock read together: a process descheduled between two reads
    (a loaded machine) would pair the wall time with a later frame, so the pair is read again until
    both frame reads fall within a millisecond."""
    for _ in range(1000):
        before = cap.frame_time_now()
        wall = time.time()
        after = cap.frame_time_now()
        if after - before <= cap.rate // 1000:
            return wall, (before + after) // 2
    raise AssertionError("could not read the wall clock and the JACK frame clock within 1 ms of each other")


@REALTIME
def test_timetagged_bundle_starts_on_time(jack_serve):
    """A bundle timetagged 0.5 s ahead starts the vibration 0.5 s after it was sent (JACK frame clock)."""
    from tests.e2e.jackutil import JackCapture, portaudio_output_ports

    client = Client(jack_serve)
    try:
        client.send("/vibsynth/glide", 0.0)
        client.request("/vibsynth/sync", 1, expect="/vibsynth/synced")
        sent: list[int] = []
        with JackCapture(7.0) as cap:
            cap.connect(portaudio_output_ports(cap.client)[:1])
            cap.arm()
            time.sleep(0.3)
            for _k in range(6):
                client.send("/vibsynth/intensity", 0.0)
                time.sleep(0.2)
                wall, frame_sent = _wall_and_frame(cap)
                bundle = encode_bundle(unix_to_ntp(wall + 0.5), [encode_message("/vibsynth/intensity", (0.8,), "f")])
                client.sock.sendto(bundle, client.target)
                time.sleep(0.7)
                sent.append(frame_sent)
            assert cap.wait()
            data, rate = cap.data[:, 0], cap.rate
            offsets = []
            for frame_sent in sent:
                due = frame_sent + int(0.5 * rate)  # the timetag on the JACK frame clock
                # through the capture's own block frames: a cycle it missed under load does not shift this
                lo, hi = cap.index_of(due - int(0.1 * rate)), cap.index_of(due + int(0.1 * rate))
                onset = np.flatnonzero(np.abs(data[lo:hi]) > 1e-7)
                if not onset.size:
                    sent_at = cap.index_of(frame_sent)
                    later = np.flatnonzero(np.abs(data[sent_at:]) > 1e-7)
                    first = (cap.frame_of(sent_at + int(later[0])) - due) / rate if later.size else None
                    raise AssertionError(
                        f"no onset within 100 ms of the timetag (the first sound after sending is at "
                        f"{first} s from the timetag; capture gaps {cap.gaps}; all onsets so far {offsets})"
                    )
                offsets.append((cap.frame_of(lo + int(onset[0])) - due) / rate)
            print(f"\ncapture gaps {cap.gaps}", end="")
    finally:
        client.close()
    print(f"\ntimetag error (onset - timetag): {', '.join(f'{1e3 * o:+.2f} ms' for o in offsets)}")
    # Each bundle started near its timetag (the loop above found every onset within 100 ms of it:
    # one applied on arrival would be 500 ms early), and their median within 10 ms. Single trials
    # are not bounded tighter: the due frame assumes the JACK frame clock keeps pace with the wall
    # clock, and a late cycle on a loaded VM shifts one trial by tens of ms (+24.7 ms seen; the
    # others of that run within 1.1 ms).
    assert float(np.median(np.abs(offsets))) < 0.010, offsets


@REALTIME
def test_load_10k_messages_per_second(jack_serve):
    port = jack_serve
    client = Client(port)
    try:
        before = client.status()
        batch = 10  # a burst every millisecond
        period = batch / LOAD_RATE
        messages = [
            encode_message(f"/vibsynth/ch/1/{'intensity' if k % 2 else 'balance'}", ((k % 100) / 100.0,), "f")
            for k in range(200)
        ]
        sent = 0
        start = time.perf_counter()
        next_t = start
        end = start + LOAD_SECONDS
        while next_t < end:
            for _ in range(batch):
                client.sock.sendto(messages[sent % 200], client.target)
                sent += 1
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        elapsed = time.perf_counter() - start
        client.request("/vibsynth/sync", 1, expect="/vibsynth/synced", timeout=20.0)
        after = client.status()
    finally:
        client.close()
    received = after["packets"] - before["packets"] - 2  # minus the /sync and the second /status
    underflows = after["underflows"] - before["underflows"]
    print(
        f"\nOSC load: sent {sent} in {elapsed:.1f} s ({sent / elapsed:.0f}/s), received {received} "
        f"(lost {sent - received}), underflows {underflows}, errors {after['errors'] - before['errors']}, "
        f"rcvbuf {after['rcvbuf']} B, render load {after['load']:.2f}"
    )
    assert after["errors"] == before["errors"]
    assert received == sent, f"lost {sent - received} of {sent} messages"
    assert_no_collapse(underflows, elapsed, f"{LOAD_RATE} OSC messages/s")


# ---------------------------------------------------------------------- issue 12: patterns and limits
def _host_address() -> str | None:
    """A non-loopback address of this machine (a client 'on another host' for the reply limit), or None."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.123", 9))  # UDP connect sends nothing: it only picks the route
        except OSError:
            return None
        address = probe.getsockname()[0]
    return None if address.startswith("127.") else address


def oscsend_to(host: str, port: int, address: str, types: str = "", *args: str) -> None:
    subprocess.run(["oscsend", host, str(port), address, *([types, *args] if types else [])], check=True, timeout=10)


def _status_from_dump(line: str) -> dict[str, str]:
    """``"key" value`` pairs of an oscdump'ed /status.reply line."""
    import re

    return dict(re.findall(r'"([a-z_0-9.]+)" (-?[0-9.e+-]+)', line))


@pytest.fixture(scope="module")
def limits_serve(tmp_path_factory):
    """serve on JACK, listening on every interface but allowing only this host (CIDR entries),
    replies to oscdump, TCP with a 2 s idle timeout and 4 connections per client address."""
    require_tools("oscsend", "oscdump")
    if not jack_available():
        unavailable("no JACK server reachable (run under scripts/with_jack.sh) or JACK-Client missing")
    host_ip = _host_address()
    allow = ["127.0.0.0/8", "::1/128", "10.0.0.0/8"] + ([f"{host_ip}/32"] if host_ip else [])
    tmp = tmp_path_factory.mktemp("osc-limits")
    dump_port = free_udp_port()
    dump = OscDump(dump_port)

    def ready(port: int) -> bool:
        oscsend(port, "/vibsynth/ping", "i", "7")
        try:
            dump.wait_for("/vibsynth/pong", timeout=0.5)
            return True
        except AssertionError:
            return False

    extra = (
        f"  reply_port: {dump_port}\n  host: 0.0.0.0\n  allow: {allow!r}\n  tcp: true\n"
        "  tcp_idle_timeout_s: 2\n  tcp_max_per_peer: 4\n"
    )
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    proc, port = start_serve(tmp, output="sounddevice", env=env, extra_config=extra, ready=ready)
    wait_for_stream(lambda: _dump_status(port, dump))
    yield port, dump, host_ip
    stop_serve(proc)
    dump.close()


def _drain(dump: OscDump) -> None:
    while not dump.lines.empty():
        dump.lines.get_nowait()


def _dump_status(port: int, dump: OscDump) -> dict[str, str]:
    oscsend(port, "/vibsynth/status")
    return _status_from_dump(dump.wait_for("/vibsynth/status.reply"))


def _error_reply_s(port: int, dump: OscDump, address: str) -> float:
    """Seconds from starting ``oscsend ADDRESS f 0.5`` to serve's ``unknown address`` reply."""
    start = time.monotonic()
    oscsend(port, address, "f", "0.5")
    line = dump.wait_for("/vibsynth/error", timeout=30.0)
    assert '"unknown address"' in line, line
    return time.monotonic() - start


def test_pathological_patterns_do_not_freeze_serve(limits_serve):
    """Patterns that made the regex backtrack for seconds to forever: answered at once, audio keeps running.

    Each is compared with the same round trip for a plain unknown address, measured first (oscsend's
    start-up and the reply path, as slow as the machine is loaded), and the underflows with those
    while the plain addresses were answered.
    """
    port, dump, _ = limits_serve
    _drain(dump)
    patterns = ["/vibsynth/" + "*" * 28 + "x", "/vibsynth/" + "*" * 245 + "x", "/vibsynth/" + "*a" * 40 + "x"]
    first = _dump_status(port, dump)
    plain = [_error_reply_s(port, dump, "/vibsynth/nothing") for _ in patterns]
    before = _dump_status(port, dump)
    times = [_error_reply_s(port, dump, pattern) for pattern in patterns]
    start = time.monotonic()
    oscsend(port, "/vibsynth/get", "s", "intensity")
    dump.wait_for("/vibsynth/intensity", timeout=30.0)
    get_s = time.monotonic() - start
    after = _dump_status(port, dump)
    rate = float(after["rate"])
    baseline = int(before["underflows"]) - int(first["underflows"])
    loaded = int(after["underflows"]) - int(before["underflows"])
    print(
        "\npathological pattern -> error reply (incl. oscsend start-up): "
        f"{', '.join(f'{1e3 * t:.0f} ms' for t in times)} "
        f"(plain address: {', '.join(f'{1e3 * t:.0f} ms' for t in plain)}); "
        f"then /get {1e3 * get_s:.0f} ms; underflows {loaded} (plain addresses: {baseline}); "
        f"stream advanced {(int(after['frame']) - int(before['frame'])) / rate:.2f} s"
    )
    # a backtracking match takes seconds to forever; a loaded machine slows the plain round trip as much
    bound = 2.0 + 2 * max(plain)
    assert max(times) < bound and get_s < bound
    frames = int(after["frame"]) - int(before["frame"])
    assert frames > 0  # the audio stream kept going
    assert_no_collapse(loaded, frames / rate, "pathological patterns answered")


def test_cidr_allow_list_starts_serve(limits_serve):
    port, dump, _ = limits_serve  # osc.allow held 127.0.0.0/8, ::1/128, 10.0.0.0/8: serve started
    status = _dump_status(port, dump)
    assert int(status["denied"]) == 0


def test_error_replies_have_no_paths_and_off_host_replies_are_small(limits_serve):
    port, dump, host_ip = limits_serve
    oscsend(port, "/vibsynth/preset", "s", "nosuch")
    line = dump.wait_for("/vibsynth/error")
    assert "unknown preset 'nosuch'" in line and str(ROOT) not in line and "/home/" not in line
    assert " shipped, 0 in presets;" in line  # the user folder by its last part only
    if host_ip is None:
        unavailable("this machine has no non-loopback IPv4 address to act as a client on another host")
    _drain(dump)
    oscsend_to(host_ip, port, "/vibsynth/status")  # 24 bytes from a non-loopback address
    line = dump.wait_for("/vibsynth/")  # the first reply: no status.reply
    assert line.startswith('/vibsynth/error ss "/vibsynth/status" "reply of'), line
    address, message = line.split('"')[1], line.split('"')[3]
    assert len(encode_message("/vibsynth/error", (address, message), "ss")) <= 3 * 24
    oscsend_to(host_ip, port, "/vibsynth/preset", "s", "nosuch")  # 32 bytes: the error is cut to 96
    line = dump.wait_for("/vibsynth/error")
    message = line.split('"')[3]
    assert message.startswith("unknown preset 'nosuch'") and message.endswith("...")
    status = _dump_status(port, dump)
    assert int(status["replies_dropped"]) >= 1 and int(status["replies_truncated"]) >= 2


def _tcp_connect(port: int, source: str) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=5.0, source_address=(source, 0))


def _tcp_ping(conn: socket.socket, value: int) -> bool:
    from vibsynth.control.osc.transport import SlipDecoder, slip_encode

    conn.settimeout(5.0)
    try:
        conn.sendall(slip_encode(encode_message("/vibsynth/ping", (value,))))
        decoder = SlipDecoder()
        while True:
            chunk = conn.recv(4096)
            if not chunk:
                return False
            if any(decode_packet(f).address == "/vibsynth/pong" for f in decoder.feed(chunk)):
                return True
    except OSError:
        return False


def _closed(conn: socket.socket, timeout: float) -> bool:
    conn.settimeout(timeout)
    try:
        return conn.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def test_stalled_tcp_clients_do_not_lock_out_others(limits_serve):
    port, dump, _ = limits_serve
    stalled = [_tcp_connect(port, "127.0.0.1") for _ in range(10)]
    try:
        for conn in stalled[:4]:
            conn.sendall(b"\xc0/vibsynth/pi")  # frames that never end
        assert all(_closed(conn, 3.0) for conn in stalled[4:])  # over 4 per address: refused
        with _tcp_connect(port, "127.0.0.2") as other:  # another address is served
            assert _tcp_ping(other, 1)
        assert all(_closed(conn, 6.0) for conn in stalled[:4])  # closed after the 2 s idle timeout
        with _tcp_connect(port, "127.0.0.1") as again:  # and the same address is served again
            assert _tcp_ping(again, 2)
    finally:
        for conn in stalled:
            conn.close()
    status = _dump_status(port, dump)
    print(f"\nTCP: refused {status['tcp_refused']}, closed idle {status['tcp_idle_closed']}")
    assert int(status["tcp_refused"]) >= 6 and int(status["tcp_idle_closed"]) >= 4


# ---------------------------------------------------------------------- issue 12: scheduled-bundle flood
def _underflows_quiet(client: Client, seconds: float) -> int:
    """Underflows over ``seconds`` with no control traffic (the baseline)."""
    before = client.status()["underflows"]
    time.sleep(seconds)
    return client.status()["underflows"] - before


@REALTIME
def test_hundred_thousand_timetagged_bundles(jack_serve):
    """100,000 bundles inside the horizon: 10,000 wait (the default cap), the rest get an error
    reply each, and the audio does not collapse (it underflowed >1000 times before the cap)."""
    port = jack_serve
    client = Client(port)  # queries; the flood comes from its own socket, which the error replies fill
    flood = Client(port)
    try:
        baseline = _underflows_quiet(client, 3.0)
        before = client.status()
        when = time.time() + 9.8  # inside the 10 s horizon on arrival; fires after the check
        sent = 0
        t0 = time.perf_counter()
        for k in range(100_000):
            tag = unix_to_ntp(when - k * 1e-5)  # later tags first: out of time order
            flood.sock.sendto(encode_bundle(tag, [encode_message("/vibsynth/intensity", (0.5,), "f")]), client.target)
            sent += 1
            if k % 100 == 99:
                time.sleep(0.005)  # ~20k/s: within what the socket buffer and the handler absorb
        flood_s = time.perf_counter() - t0
        client.request("/vibsynth/sync", 1, expect="/vibsynth/synced", timeout=30.0)
        during = client.status()
        window_s = (during["frame"] - before["frame"]) / during["rate"]
        loaded = during["underflows"] - before["underflows"]
    finally:
        client.close()
        flood.close()
    refused = during["schedule_full"] - before.get("schedule_full", 0)
    print(
        f"\n100k bundles in {flood_s:.1f} s: pending {during['scheduled_pending']}, refused {refused}, "
        f"underflows {loaded} during vs {baseline} in 3 s quiet"
    )
    assert during["scheduled_pending"] == 10_000
    bundles = during["scheduled"] - before["scheduled"]
    assert bundles == sent  # none lost in the socket
    assert refused == sent - 10_000
    assert_no_collapse(loaded, window_s, "100,000 timetagged bundles")  # the defect was >1000 in seconds


def test_liblo_oscsend_over_tcp_reaches_the_engine(limits_serve):
    """liblo frames TCP with a length prefix (OSC 1.0); the server tells it from SLIP per connection."""
    port, dump, _ = limits_serve
    subprocess.run(
        ["oscsend", f"osc.tcp://127.0.0.1:{port}", "/vibsynth/ch/1/intensity", "f", "0.375"], check=True, timeout=10
    )
    for _ in range(50):
        if _dump_status(port, dump).get("ch1.intensity") == "0.375000":
            break
        time.sleep(0.05)
    assert _dump_status(port, dump)["ch1.intensity"] == "0.375000"
    with _tcp_connect(port, "127.0.0.1") as conn:
        assert _tcp_ping(conn, 3)  # and a SLIP client still works beside it
