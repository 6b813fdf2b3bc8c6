"""Control-plane limits of the OSC server (issue 12, fault 6).

* UDP replies to a client on another host total at most 3x the request (no amplification);
* error replies never disclose file-system paths;
* ``osc.allow``: the config validator and the server parse it with one function;
* TCP: a per-address and a global connection cap, an idle timeout; stalled clients
  cannot lock others out.
"""

from __future__ import annotations

import re
import socket
import time

import pytest
import yaml

from tests.control.osc.fakes import FakeEngine, FakePeer, make_controller
from vibsynth.control.controller import Controller, KnobLimits
from vibsynth.control.osc import adapter as osc_adapter
from vibsynth.control.osc.codec import MalformedPacket, Message, decode_packet, encode_message
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.replies import REPLY_AMPLIFICATION, fit_osc_string, redact_paths
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.tables import register_tables
from vibsynth.control.osc.transport import SlipDecoder, slip_encode
from vibsynth.errors import ConfigError, PresetError
from vibsynth.settings.allow_list import AllowList, parse_allow_list
from vibsynth.settings.config import load_config
from vibsynth.settings.library import PresetLibrary

OFF_HOST = ("192.0.2.7", 40000)  # TEST-NET-1: a client on another host


class DatagramPeer(FakePeer):
    """A UDP client as the handler sees it (``datagram``: its replies are size-limited off-host)."""

    datagram = True


def _handler(ctl: Controller) -> OscHandler:
    return register_tables(OscHandler(ctl, sync_worker=None, error_reply_rate=1e9))


def _reply_bytes(peer: FakePeer) -> int:
    return sum(len(d) for d in peer.sent)


# ---------------------------------------------------------------------- reply size
def test_status_reply_off_host_is_refused_with_a_short_error():
    handler = _handler(make_controller(4))
    request = encode_message("/vibsynth/status")
    peer = DatagramPeer(OFF_HOST)
    handler.handle_packet(request, peer)
    assert [m.address for m in peer.messages()] == ["/vibsynth/error"]
    address, message = peer.errors()[0]
    assert address == "/vibsynth/status" and message.startswith("reply of")
    assert _reply_bytes(peer) <= REPLY_AMPLIFICATION * len(request)
    assert handler.stats.replies_dropped == 1 and handler.stats.replies_truncated == 1


def test_status_reply_goes_to_local_and_large_enough_requests():
    handler = _handler(make_controller(4))
    local = DatagramPeer(("127.0.0.1", 40000))
    handler.handle_packet(encode_message("/vibsynth/status"), local)
    size = len(local.sent[0])
    assert decode_packet(local.sent[0]).address == "/vibsynth/status.reply" and size > 20 * 20
    padded = encode_message("/vibsynth/status", (b"\0" * (size // REPLY_AMPLIFICATION),), "b")
    remote = DatagramPeer(OFF_HOST)
    handler.handle_packet(padded, remote)  # padding buys the room (as in QUIC)
    assert [m.address for m in remote.messages()] == ["/vibsynth/status.reply"]
    tcp = FakePeer(OFF_HOST)  # not a datagram peer: no limit
    handler.handle_packet(encode_message("/vibsynth/status"), tcp)
    assert decode_packet(tcp.sent[0]).address == "/vibsynth/status.reply"


def test_error_reply_is_cut_to_three_times_the_request():
    handler = _handler(make_controller(4))
    request = encode_message("/vibsynth/get", ("no-such-setting",))
    peer = DatagramPeer(OFF_HOST)
    handler.handle_packet(request, peer)
    ((address, message),) = peer.errors()
    assert address == "/vibsynth/get" and message.startswith("unknown setting 'no-such-setting'")
    assert message.endswith("...") and len(peer.sent[0]) <= REPLY_AMPLIFICATION * len(request)
    assert handler.stats.replies_truncated == 1
    local = DatagramPeer(("::ffff:127.0.0.1", 40000))  # the same on this host: whole message
    handler.handle_packet(request, local)
    whole = local.errors()[0][1]
    assert whole.startswith(message[:-3]) and "..." not in whole
    assert "known: intensity, balance, glide, mute, preset, texture, driver, clip" in whole


def test_random_requests_never_amplify(rng):
    """Every reply to every request (patterns, bad arguments, queries, bundles) totals <= 3x it."""
    ctl = make_controller(8)
    handler = _handler(ctl)
    for ch in range(8):
        ctl.set_knob("intensity", ch / 10.0, channels=(ch,), source="test")  # per-channel get replies
    addresses = [
        "/vibsynth/status",
        "/vibsynth/get",
        "/vibsynth/ch/*/get",
        "/vibsynth/*",
        "/vibsynth/ch/*/*",
        "/vibsynth/ping",
        "/vibsynth/preset",
        "/vibsynth/nothing",
        "/vibsynth/sync",
        "/vibsynth/notify",
        "/vibsynth/intensity",
        "/*/*",
        "/vibsynth/[x",
    ]
    values = [0.5, 7, "intensity", "texture", "nosuch", 2.5, b"\0" * 8]
    worst = 0.0
    for _ in range(2000):
        args = tuple(values[i] for i in rng.integers(0, len(values), size=int(rng.integers(0, 3))))
        request = encode_message(str(rng.choice(addresses)), args)
        peer = DatagramPeer(OFF_HOST)
        handler.handle_packet(request, peer)
        worst = max(worst, _reply_bytes(peer) / len(request))
    print(f"\nworst reply/request byte ratio off-host: {worst:.2f}")
    assert worst <= REPLY_AMPLIFICATION


def test_fit_osc_string():
    assert fit_osc_string("abc", 4) == "abc"
    assert fit_osc_string("abcdefgh", 8) == "abcd..."
    assert fit_osc_string("ééééé", 8) == "éé..."  # never cuts a UTF-8 character
    assert fit_osc_string("abcdef", 4) == "..."


# ---------------------------------------------------------------------- path redaction
@pytest.mark.parametrize(
    "text, expected",
    [
        ("/home/ana/.config/vibsynth/presets/silk.yaml:3: intensity = 2", "silk.yaml:3: intensity = 2"),
        (
            "unknown preset 'x' (3 presets in /usr/share/vibsynth/presets, /home/ana/p)",
            "unknown preset 'x' (3 presets in presets, p)",
        ),
        (r"C:\Users\ana\presets\silk.yaml: bad", "silk.yaml: bad"),
        ("~/presets/a.yaml missing", "a.yaml missing"),
        ("'/srv/x/' is not a folder", "'x' is not a folder"),
        ("speed must be >= 0 mm/s, got -1", "speed must be >= 0 mm/s, got -1"),
        ("/vibsynth/ch/1/intensity and /vibsynth/notify", "/vibsynth/ch/1/intensity and /vibsynth/notify"),
        ("a / b", "a / b"),
    ],
)
def test_redact_paths(text, expected):
    assert redact_paths(text, "/vibsynth") == expected


def test_preset_error_reply_has_no_path(tmp_path):
    user_dir = tmp_path / "home" / "ana" / "presets"
    user_dir.mkdir(parents=True)
    library = PresetLibrary(shipped_dir=None, user_dir=user_dir)
    with pytest.raises(PresetError, match=str(user_dir)):
        library.get("nosuch")  # the message names the folder ...
    ctl = Controller(FakeEngine(2), limits=KnobLimits(), preset_resolver=library.get)
    handler = _handler(ctl)
    peer = FakePeer(("127.0.0.1", 40000))
    handler.handle_packet(encode_message("/vibsynth/preset", ("nosuch",)), peer)
    ((address, message),) = peer.errors()
    assert address == "/vibsynth/preset" and message.startswith("unknown preset 'nosuch'")
    assert str(tmp_path) not in message and "/home" not in message  # ... the reply does not
    assert "0 in presets;" in message  # the folder by its last part only


def test_preset_file_error_names_only_the_file(tmp_path):
    def resolve(name):
        raise PresetError(f"{tmp_path}/presets/{name}.yaml:4: intensity = 2: outside the allowed range [0, 1]")

    handler = _handler(Controller(FakeEngine(1), limits=KnobLimits(), preset_resolver=resolve))
    peer = FakePeer(("127.0.0.1", 40000))
    handler.handle_packet(encode_message("/vibsynth/preset", ("silk",)), peer)
    assert peer.errors()[0][1] == "silk.yaml:4: intensity = 2: outside the allowed range [0, 1]"


# ---------------------------------------------------------------------- osc.allow
ACCEPTED = [
    [],
    ["127.0.0.1"],
    ["192.168.0.0/16"],
    ["10.0.0.0/8"],
    ["::1/128"],
    ["::1"],
    ["localhost"],
    ["192.168.1.7/24"],
    ["::ffff:127.0.0.0/104"],
    ["0.0.0.0/0", "::/0"],
    None,
    ["127.0.0.1", "10.0.0.0/8", "::1/128", "LocalHost"],
]
REJECTED = [
    ["somewhere"],
    ["example.com"],
    ["300.1.1.1"],
    ["10.0.0.0/33"],
    [10],
    [" 10.0.0.1"],
    "10.0.0.0/8",
    {"a": 1},
    [["127.0.0.1"]],
    ["127.0.0.1/255.0.0.0x"],
    [None],
    7,
]


def path_of(tmp_path):
    return tmp_path / "vibsynth.yaml"


def _loads_config(tmp_path, value):
    path = path_of(tmp_path)
    path.write_text(yaml.safe_dump({"version": 1, "osc": {"port": 0, "allow": value}}), encoding="utf-8")
    return path, load_config(path, env={})


def _answers_ping(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:
        client.bind(("127.0.0.1", 0))
        client.settimeout(0.3)
        client.sendto(encode_message("/vibsynth/ping", (1,)), ("127.0.0.1", port))
        try:
            return decode_packet(client.recvfrom(65536)[0]).address == "/vibsynth/pong"
        except TimeoutError:
            return False


@pytest.mark.parametrize("value", ACCEPTED + REJECTED, ids=repr)
def test_allow_values_the_config_accepts_start_the_server(tmp_path, value):
    try:
        path, config = _loads_config(tmp_path, value)
    except ConfigError as exc:
        assert value in REJECTED, f"the validator refused {value!r}: {exc}"
        assert re.match(rf"{re.escape(str(path_of(tmp_path)))}:\d+: osc.allow = ", str(exc)), str(exc)
        assert "Traceback" not in str(exc)
        return
    assert value in ACCEPTED, f"the validator accepted {value!r}"
    server = osc_adapter.create(config.settings, None, make_controller(1), None)
    server.start()  # what the validator accepts, the server takes
    try:
        allowed = parse_allow_list(value)
        assert _answers_ping(server.port) is (allowed is None or "127.0.0.1" in allowed)
    finally:
        server.stop()


def test_allow_list_membership():
    allow = parse_allow_list(["10.0.0.0/8", "::1", "192.168.1.7/24", "::ffff:172.16.0.0/108"])
    assert isinstance(allow, AllowList) and len(allow) == 4
    assert "10.200.3.4" in allow and "11.0.0.1" not in allow
    assert "::ffff:10.1.2.3" in allow  # IPv4 client on an IPv6 socket
    assert "192.168.1.200" in allow and "192.168.2.1" not in allow
    assert "172.16.9.9" in allow  # a mapped network is an IPv4 network
    assert "::1" in allow and "::2" not in allow
    assert "not an address" not in allow and "" not in allow
    assert [str(n) for n in allow][:1] == ["10.0.0.0/8"]
    assert parse_allow_list([]) is None and parse_allow_list(None) is None
    localhost = parse_allow_list(["localhost"])
    assert "127.0.0.1" in localhost and "127.9.9.9" in localhost and "::1" in localhost and "10.0.0.1" not in localhost
    with pytest.raises(ConfigError, match=r"item 1 \('example.com'\) is not an IP address or network"):
        parse_allow_list(["::1", "example.com"])
    with pytest.raises(ConfigError, match="osc.allow: item 0"):
        OscServer(make_controller(1), port=0, allow=["nowhere.invalid"])


def test_cidr_allow_list_over_udp():
    for allow, answered in ((["127.0.0.0/8"], True), (["10.0.0.0/8"], False)):
        server = OscServer(make_controller(1), port=0, allow=allow)
        server.start()
        try:
            assert _answers_ping(server.port) is answered
        finally:
            server.stop()


# ---------------------------------------------------------------------- TCP
class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _connect(port: int, source: str = "127.0.0.1") -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=5.0, source_address=(source, 0))


def _closed_by_server(conn: socket.socket, timeout: float = 3.0) -> bool:
    conn.settimeout(timeout)
    try:
        while True:
            data = conn.recv(65536)
            if not data:
                return True
    except (ConnectionResetError, BrokenPipeError):
        return True
    except TimeoutError:
        return False


def _tcp_request(conn: socket.socket, address: str, *args, expect: str) -> object:
    conn.settimeout(5.0)
    conn.sendall(slip_encode(encode_message(address, args)))
    decoder = SlipDecoder()
    while True:
        chunk = conn.recv(65536)
        assert chunk, "the server closed the connection"
        for frame in decoder.feed(chunk):
            try:
                msg = decode_packet(frame)
            except MalformedPacket:  # the tail of a push frame cut by an earlier call
                continue
            if isinstance(msg, Message) and msg.address == expect:
                return msg


def _wait_for(predicate, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


@pytest.fixture
def tcp_server():
    servers = []

    def start(**kwargs):
        clock = FakeClock()
        server = OscServer(make_controller(1), port=0, tcp=True, **kwargs)
        server.tcp.clock = clock
        server.start()
        servers.append(server)
        return server, clock

    yield start
    for server in servers:
        server.stop()


def test_stalled_connections_from_one_peer_do_not_lock_out_others(tcp_server):
    """20 stalled connections from one address (16 used to fill the server): a second address is served."""
    server, _ = tcp_server()
    stalled = [_connect(server.port) for _ in range(20)]
    try:
        for conn in stalled[:4:2]:
            conn.sendall(b"\xc0/vibsynth/pi")  # slowloris: a frame that never ends
        assert _wait_for(lambda: server.stats.tcp_refused == 16)
        assert server.tcp.connections == 4
        assert all(_closed_by_server(conn) for conn in stalled[4:])
        with _connect(server.port, source="127.0.0.2") as other:
            assert _tcp_request(other, "/vibsynth/ping", 3, expect="/vibsynth/pong").args == (3,)
    finally:
        for conn in stalled:
            conn.close()


def test_idle_connections_are_closed_and_the_peer_comes_back(tcp_server):
    server, clock = tcp_server(tcp_max_per_peer=2, tcp_idle_timeout_s=30.0)
    silent, partial = _connect(server.port), _connect(server.port)
    partial.sendall(b"\xc0/vibsynth/pi")
    refused = _connect(server.port)
    assert _closed_by_server(refused)
    active = _connect(server.port, source="127.0.0.2")
    _tcp_request(active, "/vibsynth/ping", 1, expect="/vibsynth/pong")
    clock.now += 20.0
    _tcp_request(active, "/vibsynth/ping", 2, expect="/vibsynth/pong")  # a complete packet: idle time reset
    clock.now += 20.0  # 40 s for the stalled ones
    assert _closed_by_server(silent) and _closed_by_server(partial)
    assert server.stats.tcp_idle_closed == 2
    assert _tcp_request(active, "/vibsynth/ping", 3, expect="/vibsynth/pong").args == (3,)
    with _connect(server.port) as again:  # the same address after the timeout
        assert _tcp_request(again, "/vibsynth/ping", 4, expect="/vibsynth/pong").args == (4,)
    for conn in (silent, partial, refused, active):
        conn.close()


def test_notify_subscriber_may_stay_silent_but_not_mid_frame(tcp_server):
    server, clock = tcp_server(tcp_idle_timeout_s=30.0)
    with _connect(server.port) as sub:
        _tcp_request(sub, "/vibsynth/notify", 1, expect="/vibsynth/done")
        clock.now += 100.0
        time.sleep(0.6)  # two sweeps of the idle check
        server.controller.set_knob("intensity", 0.75, source="test")
        assert _tcp_request(sub, "/vibsynth/ping", 5, expect="/vibsynth/pong").args == (5,)
        sub.sendall(b"\xc0/vibsynth/pi")
        clock.now += 100.0
        assert _closed_by_server(sub)
    assert server.stats.tcp_idle_closed == 1
    assert _wait_for(lambda: len(server.notifier) == 0)  # a closed connection is unsubscribed


def test_tcp_limits_from_the_config(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(
        "version: 1\nosc:\n  port: 0\n  tcp: true\n  tcp_max_connections: 9\n  tcp_max_per_peer: 2\n"
        "  tcp_idle_timeout_s: 5\n",
        encoding="utf-8",
    )
    server = osc_adapter.create(load_config(path, env={}).settings, None, make_controller(1), None)
    assert (server.tcp.max_connections, server.tcp.max_per_peer, server.tcp.idle_timeout_s) == (9, 2, 5.0)
    path.write_text("version: 1\nosc:\n  tcp_max_per_peer: 0\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"c.yaml:3: osc.tcp_max_per_peer = 0"):
        load_config(path, env={})
    with pytest.raises(ConfigError, match="osc.tcp_idle_timeout_s"):
        load_config(overrides={"osc.tcp_idle_timeout_s": float("nan")}, env={}, user_file=False)


def test_status_reports_the_limit_counters():
    ctl = make_controller(1)
    server = OscServer(ctl, port=0)
    pairs = dict(server.handler.status_pairs())
    for key in ("tcp_refused", "tcp_idle_closed", "replies_truncated", "replies_dropped"):
        assert pairs[key] == 0
    keys = [k for k, _ in server.handler.status_pairs()]
    assert keys.index("replies_dropped") < keys.index("ch1.intensity")
