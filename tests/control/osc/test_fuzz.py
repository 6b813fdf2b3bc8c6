"""Fuzz the OSC server: 100,000 random and malformed datagrams into the packet handler, and a
shorter burst through a real UDP socket.

Invalid-by-construction packets (truncated, wrong type tags, unknown type tags, huge strings,
nested/broken bundles, NaN/inf, out of range, unknown addresses, random bytes) must each be
counted exactly once (as malformed or as an error) and change nothing; interleaved valid
messages must produce exactly the state a simple model predicts. Random byte flips of valid
messages may or may not stay valid: state may then change only when the packet decodes and
produced no error.
"""

from __future__ import annotations

import math
import random
import socket
import struct
import time

from tests.control.osc.fakes import FakePeer, make_controller
from vibsynth.control.osc.codec import (
    IMMEDIATE,
    MalformedPacket,
    decode_packet,
    encode_bundle,
    encode_message,
    unix_to_ntp,
)
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.tables import register_tables

N_PACKETS = 100_000
CHANNELS = 4
SEED = 20260509


def _pad(raw: bytes) -> bytes:
    return raw + b"\x00" * (4 - len(raw) % 4)


class Corpus:
    """Generates packets and keeps the expected knob state of the valid ones."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.expected = {(c, k): 0.0 for c in range(CHANNELS) for k in ("intensity", "balance")}

    # ---- valid
    def valid(self) -> bytes:
        r = self.rng
        knob = r.choice(("intensity", "balance"))
        value = round(r.uniform(0.0, 1.0) if knob == "intensity" else r.uniform(-3.5, 3.5), 3)
        value = struct.unpack(">f", struct.pack(">f", value))[0]  # what a float32 carries
        if r.random() < 0.5:
            ch = r.randrange(CHANNELS)
            self.expected[(ch, knob)] = value
            return encode_message(f"/vibsynth/ch/{ch + 1}/{knob}", (value,), "f")
        for ch in range(CHANNELS):
            self.expected[(ch, knob)] = value
        if r.random() < 0.3:
            return encode_bundle(IMMEDIATE, [encode_message(f"/vibsynth/{knob}", (value,), "f")])
        return encode_message(f"/vibsynth/{knob}", (value,), "f")

    # ---- invalid by construction: (packet, number of counted errors it must produce)
    def invalid(self) -> tuple[bytes, int]:
        r = self.rng
        kind = r.randrange(12)
        good = encode_message("/vibsynth/intensity", (0.5,), "f")
        if kind == 0:  # random bytes that are neither message nor bundle
            data = bytes(r.getrandbits(8) for _ in range(r.randrange(0, 64)))
            if data[:1] == b"/" or data[:1] == b"#":
                data = b"\x00" + data[1:]
            return data, 1
        if kind == 1:  # truncated valid message
            return good[: r.randrange(1, len(good))], 1
        if kind == 2:  # wrong type tags (string or blob where a number is expected)
            tag = r.choice("sbTFN")
            arg = {"s": ("x" * r.randrange(1, 20),), "b": (b"\x01\x02",), "T": (), "F": (), "N": ()}[tag]
            return encode_message(f"/vibsynth/ch/{r.randrange(1, CHANNELS + 1)}/balance", arg, tag), 1
        if kind == 3:  # unknown type tag: undecodable
            return _pad(b"/vibsynth/intensity") + _pad(b",f" + bytes([r.choice(b"qxyzQ")])) + b"\x3f\x00\x00\x00" * 2, 1
        if kind == 4:  # huge string address (unknown)
            return encode_message("/vibsynth/" + "a" * r.randrange(1000, 60000), (0.5,), "f"), 1
        if kind == 5:  # huge string argument for a numeric knob
            return encode_message("/vibsynth/intensity", ("z" * r.randrange(1000, 20000),), "s"), 1
        if kind == 6:  # nested bundles, too deep
            inner = good
            for _ in range(r.randrange(9, 40)):
                inner = encode_bundle(IMMEDIATE, [inner])
            return inner, 1
        if kind == 7:  # bundle with a lying element size
            body = encode_bundle(IMMEDIATE, [good])
            size = r.choice([-4, 0, 3, len(good) + 4, 2**31 - 1, -(2**31)])
            return body[:16] + struct.pack(">i", size) + body[20:], 1
        if kind == 8:  # NaN / inf, alone or in a bundle
            value = r.choice([math.nan, math.inf, -math.inf])
            msg = encode_message(
                f"/vibsynth/{r.choice(['intensity', 'balance', 'glide', 'speed'])}", (value,), r.choice("fd")
            )
            return (encode_bundle(IMMEDIATE, [msg]) if r.random() < 0.5 else msg), 1
        if kind == 9:  # out of range
            msg = r.choice(
                [
                    ("/vibsynth/intensity", r.uniform(1.001, 1e6)),
                    ("/vibsynth/intensity", -r.uniform(1e-3, 10)),
                    ("/vibsynth/balance", r.uniform(3.6, 1e9)),
                    ("/vibsynth/ch/2/balance", -r.uniform(3.6, 50)),
                ]
            )
            return encode_message(msg[0], (msg[1],), "f"), 1
        if kind == 10:  # unknown address / bad pattern / wrong count
            choice = r.randrange(3)
            if choice == 0:
                return encode_message(f"/vibsynth/ch/{r.randrange(CHANNELS + 1, 1000)}/intensity", (0.5,), "f"), 1
            if choice == 1:
                return encode_message("/vibsynth/ch/[1/intensity", (0.5,), "f"), 1
            return encode_message("/vibsynth/texture", tuple(0.1 for _ in range(r.choice([0, 1, 3, 5]))), None), 1
        # kind 11: far-future bundle (beyond the horizon): every message rejected
        n = r.randrange(1, 4)
        return encode_bundle(
            unix_to_ntp(time.time() + r.uniform(20.0, 1e8)), [encode_message("/vibsynth/intensity", (0.5,), "f")] * n
        ), n

    def flipped(self) -> bytes:
        saved = dict(self.expected)
        data = bytearray(self.valid())
        self.expected = saved  # the model changes only if the handler accepts the mutated packet
        for _ in range(self.rng.randrange(1, 4)):
            data[self.rng.randrange(len(data))] = self.rng.getrandbits(8)
        return bytes(data)


def knob_state(ctl) -> dict:
    return {(c, k): getattr(s, k) for c, s in enumerate(ctl.state()) for k in ("intensity", "balance")}


def test_fuzz_handler_100k():
    rng = random.Random(SEED)
    corpus = Corpus(rng)
    ctl = make_controller(CHANNELS)
    handler = register_tables(OscHandler(ctl, error_reply_rate=1000.0))
    peer = FakePeer()
    expected_errors = 0
    flips = 0
    for _i in range(N_PACKETS):
        roll = rng.random()
        if roll < 0.15:
            handler.handle_packet(corpus.valid(), peer)
        elif roll < 0.35:
            data = corpus.flipped()
            before = knob_state(ctl)
            errors_before = handler.stats.errors + handler.stats.malformed
            handler.handle_packet(data, peer)
            after = knob_state(ctl)
            if after != before:
                decode_packet(data)  # must be valid OSC...
                assert handler.stats.errors + handler.stats.malformed == errors_before, data  # ...and accepted
                corpus.expected = after
                flips += 1
        else:
            data, n_errors = corpus.invalid()
            expected_errors += n_errors
            handler.handle_packet(data, peer)
        if len(peer.sent) > 1000:
            peer.sent.clear()
    stats = handler.stats
    assert knob_state(ctl) == corpus.expected
    errors_total = stats.errors + stats.malformed
    # every invalid-by-construction packet counted; flipped packets may add more
    assert expected_errors <= errors_total
    assert sum(ctl.error_counts.values()) == errors_total
    assert stats.malformed > 10_000 and stats.errors > 10_000
    print(
        f"\nfuzz: {N_PACKETS} packets, {stats.malformed} malformed, {stats.errors} errors "
        f"({expected_errors} from invalid-by-construction), {flips} byte-flipped packets changed state legitimately, "
        f"{stats.error_replies_suppressed} error replies rate-limited"
    )


def test_invalid_packets_counted_exactly_once():
    rng = random.Random(SEED + 1)
    corpus = Corpus(rng)
    ctl = make_controller(CHANNELS)
    handler = register_tables(OscHandler(ctl))
    before = knob_state(ctl)
    expected = 0
    for _ in range(5000):
        data, n = corpus.invalid()
        expected += n
        handler.handle_packet(data, FakePeer())
    assert handler.stats.errors + handler.stats.malformed == expected
    assert knob_state(ctl) == before and ctl.engine.commands == []


def test_decoder_only_raises_malformed():
    rng = random.Random(SEED + 2)
    seeds = [
        encode_message("/vibsynth/ch/1/texture", (0.5, 1.0), "ff"),
        encode_bundle(
            IMMEDIATE, [encode_message("/a", (1, "s", b"b"), "isb"), encode_bundle(5, [encode_message("/b")])]
        ),
    ]
    for _ in range(20000):
        data = bytearray(rng.choice(seeds))
        for _ in range(rng.randrange(1, 6)):
            op = rng.randrange(3)
            if op == 0 and data:
                data[rng.randrange(len(data))] = rng.getrandbits(8)
            elif op == 1 and data:
                del data[rng.randrange(len(data)) :]
            else:
                data += bytes(rng.getrandbits(8) for _ in range(4))
        try:
            decode_packet(bytes(data))
        except MalformedPacket:
            pass


def ping(client: socket.socket, target: tuple, token: int, attempts: int = 30) -> bool:
    """Ping until the pong with ``token`` arrives (the burst may have overflowed the receive buffer)."""
    client.settimeout(1.0)
    for _ in range(attempts):
        client.sendto(encode_message("/vibsynth/ping", (token,), "i"), target)
        try:
            while True:  # rate-limited error replies of the burst may arrive first
                msg = decode_packet(client.recvfrom(65536)[0])
                if msg.address == "/vibsynth/pong" and msg.args == (token,):
                    return True
        except TimeoutError:
            continue
    return False


def test_socket_burst_server_survives():
    rng = random.Random(SEED + 3)
    corpus = Corpus(rng)
    ctl = make_controller(CHANNELS)
    server = OscServer(ctl, port=0)
    server.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(5.0)
    target = ("127.0.0.1", server.port)
    try:
        sent = 0
        for _ in range(3000):
            data, _ = corpus.invalid()
            try:
                client.sendto(data, target)
                sent += 1
            except OSError:  # e.g. a packet larger than the loopback MTU allows
                pass
        assert ping(client, target, 1) and knob_state(ctl) == {k: 0.0 for k in corpus.expected}
        client.sendto(encode_message("/vibsynth/ch/3/intensity", (0.25,), "f"), target)
        assert ping(client, target, 2)
        state = knob_state(ctl)
        assert state[(2, "intensity")] == 0.25
        assert all(v == 0.0 for k, v in state.items() if k != (2, "intensity"))
        received = server.counters()["packets"]
        counted = server.handler.stats.errors + server.handler.stats.malformed
        assert server.stats.handler_errors == 0 and counted > 0
        print(
            f"\nsocket burst: sent {sent} + 2, received {received}, counted errors {counted}, "
            f"rcvbuf {server.udp.rcvbuf} bytes"
        )
    finally:
        client.close()
        server.stop()


def test_fuzz_batches_match_the_model():
    """The batching path (coalescing) gives the same state and the same error count."""
    rng = random.Random(SEED + 4)
    corpus = Corpus(rng)
    ctl = make_controller(CHANNELS)
    handler = register_tables(OscHandler(ctl, error_reply_rate=1000.0))
    peer = FakePeer()
    expected_errors = 0
    for _ in range(500):
        batch = []
        for _ in range(rng.randrange(1, 64)):
            if rng.random() < 0.5:
                batch.append((corpus.valid(), peer))
            else:
                data, n = corpus.invalid()
                expected_errors += n
                batch.append((data, peer))
        handler.handle_batch(batch)
        peer.sent.clear()
    assert knob_state(ctl) == corpus.expected
    assert handler.stats.errors + handler.stats.malformed == expected_errors
