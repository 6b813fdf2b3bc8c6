"""vibsynth.Client against a real OSC server (in-process OscServer, real Controller and Engine on a tiny bank).

Also: a fake server that answers garbage, and a property test that python-osc (the client's
codec) and the server's own codec read each other's packets identically.
"""

from __future__ import annotations

import logging
import math
import pickle
import random
import socket
import struct
import threading
import time

import numpy as np
import pytest

from tests.control.osc.fakes import resolve_preset
from vibsynth.app.client import (
    IMMEDIATELY,
    Client,
    Reply,
    encode_bundle,
    encode_message,
    parse_packet,
)
from vibsynth.control.controller import Controller
from vibsynth.control.osc import codec
from vibsynth.control.osc.server import OscServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import NullOutput
from vibsynth.errors import NoReplyError, ParameterError, ServerError, VibsynthError


@pytest.fixture(scope="module")
def bank(basis):
    return build_bank(basis, BankSpec(fs=48000.0, loop_seconds=0.5, levels=9, seed=2))


def _serve(bank, *, render: bool):
    engine = Engine(bank, channels=3, glide_s=0.0, max_block=512)
    ctl = Controller(engine, initial_glide_s=0.0, preset_resolver=resolve_preset)
    output = NullOutput(engine, block_size=128) if render else None
    if output is not None:
        output.start()
    server = OscServer(ctl, port=0)
    server.start()
    return engine, ctl, server, output


@pytest.fixture
def live(bank):
    """A server whose engine renders in real time (a silent output), as ``vibsynth serve --output null``."""
    engine, ctl, server, output = _serve(bank, render=True)
    try:
        yield engine, ctl, server
    finally:
        server.stop()
        output.stop()


@pytest.fixture
def manual(bank):
    """A server whose engine renders only when the test says (explicit stream time)."""
    engine, ctl, server, _ = _serve(bank, render=False)
    try:
        yield engine, ctl, server
    finally:
        server.stop()


@pytest.fixture
def silent_port():
    """A bound UDP port that never answers."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        yield sock.getsockname()[1]
    finally:
        sock.close()


# ---------------------------------------------------------------------- set / get
def test_set_get_round_trips(live):
    engine, ctl, server = live
    with Client(port=server.port) as c:
        c.set_intensity(0.25, channel=2)
        c.set_texture(0.5, -1.25, channel=3)
        c.set_balance(1.5)  # every channel
        c.set_glide(150, channel=1)
        c.mute(channel=3)
        c.sync()
        assert c.get("intensity", 2) == pytest.approx(0.25)
        assert c.get("intensity", 3) == pytest.approx(0.5)
        assert [c.get("balance", n) for n in (1, 2, 3)] == [1.5, 1.5, 1.5]
        assert c.get("texture", 2) == (pytest.approx(0.25), 1.5)
        assert c.get("glide", 1) == pytest.approx(150.0) and c.get("glide", 2) == 0.0
        assert c.get("mute", 3) is True and c.get("mute", 1) is False
        assert c.get("preset") is None
        c.unmute(channel=3)
        c.preset("silk", channel=1)
        c.sync()
        assert c.get("mute", 3) is False
        assert c.get("preset", 1) == "silk" and c.get("intensity", 1) == pytest.approx(0.3)
        assert ctl.get("intensity", 1) == pytest.approx(0.25)  # the server's own view (0-based)
        assert c.get("driver", 2) == "knobs"
        ctl.drive("clip", channels=[1], intensity=0.9)
        assert c.get("driver", 2) == "clip" and c.get("driver", 1) == "knobs"
        c.panic()
        c.sync()
        assert c.get("intensity", 2) == 0.0
        assert c.ping() > 0.0


def test_status_is_a_dict(live):
    engine, ctl, server = live
    with Client(port=server.port, timeout=2.0) as c:
        c.set_intensity(0.5, channel=1)
        status = c.status()
    import vibsynth

    assert status["version"] == vibsynth.__version__
    assert status["channels"] == 3 and status["rate"] == 48000.0
    assert status["ch1.intensity"] == pytest.approx(0.5) and status["ch2.intensity"] == 0.0
    assert isinstance(status["frame"], int) and status["frame"] >= 0


def test_arguments_are_checked_before_sending(live):
    engine, ctl, server = live
    with Client(port=server.port) as c:
        for call in (
            lambda: c.set_intensity(1.5),
            lambda: c.set_intensity(math.nan),
            lambda: c.set_balance("1"),
            lambda: c.set_glide(-1),
            lambda: c.set_intensity(0.5, channel=0),
            lambda: c.set_intensity(0.5, channel=True),
            lambda: c.preset(""),
            lambda: c.get("loudness"),
            lambda: c.at(-1),
            lambda: c.send("no-slash"),
        ):
            with pytest.raises(ParameterError):
                call()
        assert c.stats.sent == 0
    with pytest.raises(ParameterError, match="port"):
        Client(port=99999)
    with pytest.raises(ParameterError, match="timeout"):
        Client(timeout=math.nan)


# ---------------------------------------------------------------------- errors and timeouts
def test_server_error_replies_raise_server_error(live):
    engine, ctl, server = live
    with Client(port=server.port) as c:
        with pytest.raises(ServerError) as info:
            c.get("intensity", channel=9)
        assert info.value.address == "/vibsynth/ch/9/get"
        assert "channel 9" in info.value.message
        assert isinstance(info.value, VibsynthError)
        # fire-and-forget commands: refusals are reported by the next sync(), all of them
        c.set_balance(99.0)
        c.preset("no-such-preset", channel=2)
        c.set_intensity(0.4, channel=1)
        with pytest.raises(ServerError) as info:
            c.sync()
        assert info.value.address == "/vibsynth/balance"
        assert "outside the allowed range" in info.value.message
        assert [a for a, _ in info.value.errors] == ["/vibsynth/balance", "/vibsynth/ch/2/preset"]
        assert "unknown preset" in info.value.errors[1][1]
        copy = pickle.loads(pickle.dumps(info.value))  # crosses process boundaries intact
        assert (type(copy), str(copy), copy.errors) == (ServerError, str(info.value), info.value.errors)
        c.sync()  # reported once
        assert c.get("intensity", 1) == pytest.approx(0.4)  # the valid one was applied
        assert c.get("balance", 1) == 0.0


def test_no_reply_raises_within_the_timeout(silent_port):
    with Client(port=silent_port, timeout=5.0) as c:
        timings = []
        for timeout in (0.05, 0.3):
            started = time.monotonic()
            with pytest.raises(NoReplyError) as info:
                c.get("intensity", timeout=timeout)
            timings.append(time.monotonic() - started)
            assert isinstance(info.value, TimeoutError)
            assert f"127.0.0.1:{silent_port}" in str(info.value) and f"{timeout!r} s" in str(info.value)
            assert (info.value.host, info.value.port, info.value.timeout) == ("127.0.0.1", silent_port, timeout)
        assert timings[0] >= 0.05 and timings[1] >= 0.3
        assert timings[0] < timings[1] < 0.3 + 2.0
        with pytest.raises(NoReplyError):
            c.status(timeout=0.01)


# ---------------------------------------------------------------------- bundles
def _knob_change_frame(engine, channel, before, block=96, limit_s=1.0):
    """Render until channel's (intensity, balance) differs from ``before``; the frame it changed in."""
    for _ in range(int(limit_s * engine.fs / block)):
        start = engine.frame_position
        engine.render(block)
        if engine.knob_values()[channel][:2] != before:
            return start
    raise AssertionError("the knobs never changed")


def test_timetagged_bundles_apply_at_their_frame(manual):
    engine, ctl, server = manual
    fs = engine.fs
    engine.render(4800)
    with Client(port=server.port) as c:
        c.ping()  # the server's stream clock has seen the engine
        start = engine.frame_position
        with c.at(0.4) as late:
            late.set_intensity(0.9, channel=1)
            late.set_balance(1.0, channel=1)
        with c.at(0.15) as early:
            early.set_texture(0.5, -1.0, channel=2)
        c.ping()
        assert engine.stats.pending == 4  # waiting in the engine (texture = 2 moves), not applied yet
        # get answers the targets at once (scheduled moves included)
        assert c.get("intensity", 1) == pytest.approx(0.9) and c.get("texture", 2) == (0.5, -1.0)
        assert engine.knob_values()[0][:2] == (0.0, 0.0)
        early_frame = _knob_change_frame(engine, 1, (0.0, 0.0))
        assert engine.knob_values()[0][:2] == (0.0, 0.0)  # the later bundle is still waiting
        late_frame = _knob_change_frame(engine, 0, (0.0, 0.0))
    assert start < early_frame < late_frame
    assert 0.05 * fs < early_frame - start <= 0.15 * fs + 96
    assert 0.2 * fs < late_frame - early_frame < 0.3 * fs
    intensity, balance, _ = engine.knob_values()[0]
    assert intensity == pytest.approx(0.9) and balance == 1.0  # both moves of one bundle in one block
    assert engine.stats.pending == 0


def test_immediate_bundle_and_absolute_time(live):
    engine, ctl, server = live
    with Client(port=server.port) as c:
        with c.bundle() as b:
            b.set_intensity(0.2, channel=1)
            b.set_intensity(0.7, channel=2)
            b.add("/vibsynth/ch/3/glide", 40.0)
        c.sync()
        assert (c.get("intensity", 1), c.get("intensity", 2), c.get("glide", 3)) == (
            pytest.approx(0.2),
            pytest.approx(0.7),
            pytest.approx(40.0),
        )
        with c.at(time.time() + 0.05) as sent:  # a Unix time
            sent.mute(channel=1)
        with pytest.raises(ValueError), c.bundle() as b:  # an exception in the block: nothing sent
            b.set_intensity(1.0, channel=1)
            raise ValueError("oops")
        time.sleep(0.15)
        c.sync()
        assert c.get("mute", 1) is True and c.get("intensity", 1) == pytest.approx(0.2)
        with pytest.raises(RuntimeError):
            sent.set_intensity(0.5)  # a bundle is sent once
        with c.at(60.0) as b:  # beyond the server's 10 s horizon
            b.set_intensity(0.5, channel=1)
        with pytest.raises(ServerError, match="horizon"):
            c.sync()


# ---------------------------------------------------------------------- robustness
class _FakeServer:
    """Answers every request with ``replies(request)`` datagrams."""

    def __init__(self, replies) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.replies = replies
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            try:
                data, peer = self.sock.recvfrom(65536)
            except OSError:
                continue
            for reply in self.replies(data):
                self.sock.sendto(reply, peer)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.sock.close()


def _nested(depth: int) -> bytes:
    packet = encode_message("/vibsynth/ch/1/intensity", (0.5,), "f")
    for _ in range(depth):
        packet = b"#bundle\x00" + struct.pack(">Q", 1) + struct.pack(">i", len(packet)) + packet
    return packet


GARBAGE = [
    b"",
    b"\x00",
    b"/vi",
    b"#bundle\x00\x00\x00",
    b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\xff\xff\xff\xfc" + b"/x\x00\x00",  # negative element size
    b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\x00\x00\x01\x00" + b"/x\x00\x00",  # element past the end
    _nested(50),  # deeper than the limit (python-osc alone would recurse)
    b"/\xff\xfe\x00,f\x00\x00\x00\x00\x00\x00",  # address not UTF-8
    b"/vibsynth/ch/1/intensity\x00\x00\x00\x00,q\x00\x00",  # unknown type tag
    b"/vibsynth/ch/1/intensity\x00\x00\x00\x00,f\x00\x00",  # float missing
    b"/vibsynth/ch/1/intensity\x00\x00\x00\x00,b\x00\x00\xff\xff\xff\xff",  # negative blob size
    encode_message("/vibsynth/ch/1/intensity", ("loud",), "s"),  # right address, wrong shape
    encode_message("/vibsynth/error", (3,), "i"),  # an error reply of the wrong shape
    encode_message("/vibsynth/ch/2/intensity", (0.1,), "f"),  # someone else's answer
    bytes(range(256)),
]


def test_garbage_replies_are_counted_and_ignored(caplog):
    fake = _FakeServer(lambda request: [*GARBAGE, encode_message("/vibsynth/ch/1/intensity", (0.75,), "f")])
    try:
        with caplog.at_level(logging.DEBUG), Client(port=fake.port, timeout=2.0) as c:
            assert c.get("intensity", 1) == 0.75
            assert c.stats.malformed >= len(GARBAGE) - 2
            assert c.stats.ignored >= 1
        assert not [r for r in caplog.records if r.levelno >= logging.WARNING]  # python-osc's warnings avoided
    finally:
        fake.close()
    only_garbage = _FakeServer(lambda request: GARBAGE)
    try:
        with Client(port=only_garbage.port, timeout=0.3) as c:
            with pytest.raises(NoReplyError):
                c.get("intensity", 1)
            with pytest.raises(NoReplyError):
                c.status()
    finally:
        only_garbage.close()


def test_random_datagrams_never_raise(rng):
    valid = [
        encode_message("/vibsynth/ch/1/intensity", (0.5,), "f"),
        encode_message("/vibsynth/status.reply", ("version", "0.1.0", "channels", 2), "sssi"),
        encode_bundle(IMMEDIATELY, [encode_message("/a", (1, "x", b"\x01"), "isb"), _nested(3)]),
    ]
    for _ in range(3000):
        data = bytearray(valid[int(rng.integers(len(valid)))])
        for _ in range(int(rng.integers(1, 6))):
            kind = int(rng.integers(3))
            if kind == 0 and data:
                data[int(rng.integers(len(data)))] = int(rng.integers(256))
            elif kind == 1:
                del data[int(rng.integers(len(data) + 1)) :]
            else:
                data += bytes(rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8))
        result = parse_packet(bytes(data))
        assert result is None or all(isinstance(r, Reply) for r in result)
    for _ in range(1000):
        result = parse_packet(bytes(rng.integers(0, 256, int(rng.integers(0, 64)) * 4, dtype=np.uint8)))
        assert result is None or isinstance(result, list)


def test_two_clients_at_once(live):
    engine, ctl, server = live
    failures: list[BaseException] = []

    def drive(channel: int, values: list[float]) -> None:
        try:
            with Client(port=server.port, timeout=2.0) as c:
                for value in values:
                    c.set_intensity(value, channel=channel)
                    assert c.get("intensity", channel) == pytest.approx(value)
                    assert c.ping() >= 0.0
        except BaseException as exc:  # noqa: BLE001 - reported below
            failures.append(exc)

    values = [[(i % 10) / 10 for i in range(40)], [((i + 5) % 10) / 10 for i in range(40)]]
    threads = [threading.Thread(target=drive, args=(n + 1, values[n])) for n in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not failures, failures
    with Client(port=server.port) as a, Client(port=server.port) as b:
        assert a.local_address != b.local_address
        assert a.get("intensity", 1) == pytest.approx(values[0][-1])
        assert b.get("intensity", 2) == pytest.approx(values[1][-1])


# ---------------------------------------------------------------------- codec cross-check
_CHARS = "abcXYZ019_-.éß漢🙂 "


def _random_args(r: random.Random, tags: str) -> list[object]:
    args: list[object] = []
    for tag in tags:
        if tag == "i":
            args.append(r.randrange(-(2**31), 2**31))
        elif tag == "h":
            args.append(r.randrange(-(2**63), 2**63))
        elif tag == "f":
            args.append(struct.unpack(">f", struct.pack(">f", r.uniform(-1e6, 1e6)))[0])
        elif tag == "d":
            args.append(r.uniform(-1e300, 1e300) if r.random() < 0.5 else r.uniform(-1, 1))
        elif tag in "sS":
            args.append("".join(r.choice(_CHARS) for _ in range(r.randrange(0, 12))))
        elif tag == "c":
            args.append(r.choice(_CHARS))
        elif tag == "b":
            args.append(bytes(r.randrange(256) for _ in range(r.randrange(0, 9))))
        elif tag == "t":
            args.append(r.randrange(0, 2**64))
        elif tag == "T":
            args.append(True)
        elif tag == "F":
            args.append(False)
        elif tag == "N":
            args.append(None)
        elif tag == "I":
            args.append(math.inf)
    return args


def _random_message(r: random.Random, alphabet: str) -> tuple[str, list[object], str]:
    address = "/" + "/".join("".join(r.choice(_CHARS[:-1]) for _ in range(r.randrange(1, 6))) for _ in range(3))
    tags = "".join(r.choice(alphabet) for _ in range(r.randrange(0, 7)))
    return address, _random_args(r, tags), tags


def test_python_osc_and_the_server_codec_agree():
    r = random.Random(20261121)
    for _ in range(500):
        # client (python-osc) -> server codec
        address, args, tags = _random_message(r, "ihfdsScbtTFNI")
        message = codec.decode_packet(encode_message(address, args, tags))
        assert (message.address, list(message.args), message.types) == (address, args, tags)
        # server codec -> client (python-osc); python-osc reads 't' as a datetime: not compared
        address, args, tags = _random_message(r, "ihfdsScbTFNI")
        (reply,) = parse_packet(codec.encode_message(address, args, tags))
        assert (reply.address, list(reply.args), reply.types) == (address, args, tags)


def test_bundles_agree_both_ways():
    r = random.Random(7)
    for _ in range(200):
        messages = [_random_message(r, "ifsdhb") for _ in range(r.randrange(1, 5))]
        when = IMMEDIATELY if r.random() < 0.3 else time.time() + r.uniform(-100, 100)
        inner = encode_bundle(when, [encode_message(*m) for m in messages[1:]])
        bundle = codec.decode_packet(encode_bundle(when, [encode_message(*messages[0]), inner]))
        flat = list(codec.iter_messages(bundle))
        assert [(m.address, list(m.args), m.types) for m, _ in flat] == [tuple(m) for m in messages]
        if when == IMMEDIATELY:
            assert bundle.timetag == codec.IMMEDIATE
        else:
            assert abs(codec.ntp_to_unix(bundle.timetag) - when) < 1e-5
        # server -> client: flattened in order (one timetag)
        tag = codec.IMMEDIATE if when == IMMEDIATELY else codec.unix_to_ntp(when)
        data = codec.encode_bundle(tag, [codec.encode_message(*m) for m in messages])
        assert [(p.address, list(p.args), p.types) for p in parse_packet(data)] == [tuple(m) for m in messages]
