"""The C# client's OSC codec and argument checks (clients/csharp/VibsynthClient.cs), run with mono.

The encoder is checked byte for byte against python-osc (an implementation no one here wrote);
the decoder against python-osc's packets, malformed packets, and, on random mutations of valid
packets, against the server's own strict decoder (same verdict, same values). No server runs:
the argument checks use a port nothing listens on and count what was sent.
"""

from __future__ import annotations

import calendar
import datetime as dt
import struct

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from tests.clients.mono import run_mono
from vibsynth.control.osc import codec


def pyosc(address: str, *args: tuple[str, object]) -> bytes:
    """A message built by python-osc from ``(tag, value)`` pairs."""
    builder = OscMessageBuilder(address)
    for tag, value in args:
        builder.add_arg(value, tag)
    return builder.build().dgram


def pyosc_bundle(when: float, *elements: bytes) -> bytes:
    """A bundle built by python-osc from encoded messages and bundles (parsed back into its objects first)."""
    builder = OscBundleBuilder(when)
    for data in elements:
        builder.add_content(OscBundle(data) if OscBundle.dgram_is_bundle(data) else OscMessage(data))
    return builder.build().dgram


# 2024-03-01 12:00:00.25 UTC, as ClientCheck.cs writes it
WHEN = calendar.timegm(dt.datetime(2024, 3, 1, 12, 0, 0).timetuple()) + 0.25


@pytest.fixture(scope="module")
def encoded(client_check) -> dict[str, str]:
    return run_mono(client_check, "encode")


def test_messages_are_byte_identical_to_python_osc(encoded):
    expected = {
        "empty": pyosc("/vibsynth/panic"),
        "float": pyosc("/vibsynth/ch/2/intensity", ("f", 0.5)),
        "texture": pyosc("/vibsynth/texture", ("f", 0.25), ("f", -1.75)),
        "int": pyosc("/vibsynth/mute", ("i", 1)),
        "negative_int": pyosc("/x", ("i", -123456789)),
        "string3": pyosc("/vibsynth/preset", ("s", "abc")),
        "string4": pyosc("/vibsynth/preset", ("s", "abcd")),
        "unicode": pyosc("/vibsynth/preset", ("s", "velours-été-触")),
        "mixed": pyosc("/vibsynth/ch/1/play", ("s", "impact"), ("f", 0.8), ("f", 1.5), ("i", 3)),
        "double_long": pyosc("/d", ("d", 3.141592653589793), ("h", 1 << 40)),
        "blob5": pyosc("/b", ("b", bytes([1, 2, 3, 4, 5]))),
        "bools": pyosc("/t", ("T", True), ("F", False)),
        "float_special": pyosc("/f", ("f", 1e-38), ("f", -0.0), ("f", 3.4e38)),
    }
    for name, data in expected.items():
        assert encoded[name] == data.hex(), name
    # python-osc refuses an empty blob; the server's codec writes its size 0
    assert encoded["blob0"] == codec.encode_message("/b", (b"",), "b").hex()


def test_bundles_are_byte_identical_to_python_osc(encoded):
    inner = (pyosc("/vibsynth/ch/1/intensity", ("f", 0.5)), pyosc("/vibsynth/ch/2/balance", ("f", 1.0)))
    assert encoded["bundle_now"] == pyosc_bundle(IMMEDIATELY, *inner).hex()
    assert encoded["bundle_at"] == pyosc_bundle(WHEN, *inner).hex()
    assert int(encoded["bundle_at_ntp"]) == codec.unix_to_ntp(WHEN)
    assert encoded["bundle_at_roundtrip"] == "true"
    nested = bytes.fromhex(encoded["nested"])
    outer = codec.decode_packet(nested)
    assert isinstance(outer, codec.Bundle) and outer.timetag == codec.IMMEDIATE
    assert [e.timetag for e in outer.elements] == [codec.unix_to_ntp(WHEN)]
    assert nested[20:] == pyosc_bundle(WHEN, *inner)


def test_a_client_bundle_holds_each_command_in_the_servers_form(encoded):
    packet = codec.decode_packet(bytes.fromhex(encoded["commands"]))
    assert isinstance(packet, codec.Bundle) and packet.timetag == codec.unix_to_ntp(WHEN)
    got = [(m.address, m.types, m.args) for m in packet.elements]
    assert got == [
        ("/vibsynth/ch/2/texture", "ff", (pytest.approx(0.6), -0.5)),
        ("/vibsynth/intensity", "f", (0.25,)),
        ("/vibsynth/ch/3/mute", "i", (1,)),
        ("/vibsynth/glide", "f", (150.0,)),
        ("/vibsynth/ch/1/preset", "s", ("velvet",)),
        ("/vibsynth/source/4/pos", "fff", (pytest.approx(0.01), pytest.approx(-0.02), 0.5)),
        ("/vibsynth/source/4/rolloff", "s", ("inverse-square",)),
        ("/vibsynth/ch/2/play", "sffi", ("heartbeat", 0.5, 2.0, 4)),
        ("/vibsynth/ch/2/stop", "f", (80.0,)),
        ("/vibsynth/panic", "", ()),
    ]
    assert encoded["commands_count"] == "10"
    assert encoded["sent"] == "0"  # building a bundle sends nothing


def test_now_plus_delay_is_the_wall_clock_plus_delay(encoded):
    # the same process read the system clock right after: within a few ms (JIT, scheduling)
    assert abs(float(encoded["from_now_0.5"]) - 0.5) < 0.05


# ---------------------------------------------------------------------- decoding
def _canonical(message: codec.Message, timetag: int) -> str:
    """What ClientCheck.cs prints for one decoded message (see Canonical there)."""
    fields = [str(timetag), message.address.encode().hex(), message.types or "-"]
    for tag, value in zip(message.types, message.args):
        if tag == "f":
            fields.append(struct.pack(">f", value).hex())
        elif tag == "d":
            fields.append(struct.pack(">d", value).hex())
        elif tag in "sS":
            fields.append(value.encode().hex() + ".")
        elif tag == "b":
            fields.append(bytes(value).hex() + ".")
        elif tag in "TFNI":
            fields.append(tag)
        elif tag == "c":
            fields.append(str(ord(value)) if isinstance(value, str) else str(value))
        else:
            fields.append(str(int(value)))
    return " ".join(fields)


def _server_view(data: bytes) -> str:
    """The server codec's decoding of a packet in ClientCheck's canonical form ("null" when it refuses)."""
    try:
        packet = codec.decode_packet(data)
    except codec.MalformedPacket:
        return "null"
    return " | ".join(_canonical(m, 1 if t == codec.IMMEDIATE else t) for m, t in codec.iter_messages(packet))


def _decode(client_check, packets: list[bytes]) -> list[str]:
    found = run_mono(client_check, "decode", *(p.hex() for p in packets))
    return [found[f"packet{i + 1}"] for i in range(len(packets))]


def _valid_packets() -> list[bytes]:
    m1 = pyosc("/vibsynth/ch/1/intensity", ("f", 0.5))
    m2 = pyosc("/vibsynth/status.reply", ("s", "version"), ("s", "0.1.0"), ("s", "channels"), ("i", 2))
    m3 = pyosc("/vibsynth/error", ("s", "/vibsynth/intensity"), ("s", "intensity 1.5 is outside [0, 1] — é"))
    m4 = pyosc("/x", ("d", -2.5), ("h", -(1 << 50)), ("b", b"\x00\xff\x10"), ("T", True), ("F", False), ("N", None))
    m5 = pyosc("/vibsynth/ch/3/texture", ("f", 1.0), ("f", -3.5))
    return [
        m1,
        m2,
        m3,
        m4,
        pyosc_bundle(IMMEDIATELY, m1, m5),
        pyosc_bundle(WHEN, m2, pyosc_bundle(WHEN + 1.0, m3)),
        pyosc_bundle(WHEN, pyosc_bundle(IMMEDIATELY, m5)),  # "immediately" inside: the enclosing time
        codec.encode_message("/c", ("z", 2**40), "ct"),
        codec.encode_message("/i", (), "I"),
    ]


def test_decoder_reads_python_osc_packets_as_the_server_does(client_check):
    packets = _valid_packets()
    decoded = _decode(client_check, packets)
    for packet, got in zip(packets, decoded):
        assert got != "null"
        assert got == _server_view(packet)
    # spot checks in plain words
    assert decoded[0] == f"1 {b'/vibsynth/ch/1/intensity'.hex()} f 3f000000"
    inner_time = codec.unix_to_ntp(WHEN)
    assert decoded[6].startswith(f"{inner_time} ")


def test_decoder_refuses_malformed_packets(client_check):
    good = pyosc("/vibsynth/ch/1/intensity", ("f", 0.5))
    blob = pyosc("/b", ("b", b"abcde"))
    bundle = pyosc_bundle(IMMEDIATELY, good)
    nested = good
    for _ in range(9):
        nested = pyosc_bundle(IMMEDIATELY, nested)
    bad = {
        "empty": b"",
        "not a multiple of 4": good[:-1],
        "truncated float": good[:-4],
        "no NUL in address": b"/abc",
        "bad address padding": b"/a\x00x,\x00\x00\x00",
        "type tags without comma": b"/ab\x00f\x00\x00\x00\x00\x00\x00\x00",
        "unknown type tag": b"/ab\x00,q\x00\x00\x00\x00\x00\x00",
        "array tags": b"/ab\x00,[]\x00",
        "trailing bytes": good + b"\x00\x00\x00\x00",
        "non-UTF-8 string": b"/ab\x00,s\x00\x00\xff\xfe\x00\x00",
        "blob size beyond the packet": blob[:8] + struct.pack(">i", 4096) + blob[12:],
        "negative blob size": blob[:8] + struct.pack(">i", -4) + blob[12:],
        "blob padding not zero": blob[:-1] + b"\x01",
        "bundle element size beyond": bundle[:16] + struct.pack(">i", 4096) + bundle[20:],
        "bundle element size negative": bundle[:16] + struct.pack(">i", -8) + bundle[20:],
        "bundle element size unaligned": bundle[:16] + struct.pack(">i", len(good) - 2) + bundle[20:],
        "bundle shorter than its header": b"#bundle\x00\x00\x00\x00\x00",
        "bundle nested 10 deep": nested,
        "neither message nor bundle": b"xyz\x00",
    }
    decoded = _decode(client_check, list(bad.values()))
    for name, got in zip(bad, decoded):
        assert got == "null", name
    assert _decode(client_check, [pyosc_bundle(IMMEDIATELY)])[0] == ""  # an empty bundle is valid, no messages


def test_decoder_agrees_with_the_server_on_random_mutations(client_check, rng):
    """Flip, cut and splice bytes of valid packets: where the server's strict decoder accepts, the
    client reads the same values; the client never crashes. (The client is stricter in one place:
    padding bytes must be NUL, as OSC 1.0 says.)"""
    seeds = _valid_packets()
    packets = []
    for _ in range(600):
        data = bytearray(seeds[int(rng.integers(len(seeds)))])
        kind = int(rng.integers(3))
        if kind == 0:
            for _ in range(int(rng.integers(1, 4))):
                data[int(rng.integers(len(data)))] = int(rng.integers(256))
        elif kind == 1:
            data = data[: int(rng.integers(len(data) + 1))]
        else:
            cut = int(rng.integers(len(data) + 1))
            data = data[:cut] + bytes(int(x) for x in rng.integers(0, 256, size=int(rng.integers(0, 9)))) + data[cut:]
        packets.append(bytes(data))
    decoded = []
    for start in range(0, len(packets), 150):  # a bounded command line per run
        decoded += _decode(client_check, packets[start : start + 150])
    accepted_by_server = 0
    for packet, got in zip(packets, decoded):
        server = _server_view(packet)
        if server == "null" or got == "null":
            continue
        accepted_by_server += 1
        assert _same(got, server), packet.hex()
    assert accepted_by_server > 50  # the mutations exercised the value paths, not only refusals


def _same(client: str, server: str) -> bool:
    """Equal canonical forms, where a float32 NaN matches any NaN (its payload may change in Python)."""
    a, b = client.split(), server.split()
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x == y:
            continue
        if len(x) == 8 and len(y) == 8 and all(np.isnan(struct.unpack(">f", bytes.fromhex(v))[0]) for v in (x, y)):
            continue
        return False
    return True


# ---------------------------------------------------------------------- argument checks
def test_bad_arguments_raise_argument_exceptions_and_send_nothing(client_check):
    found = run_mono(client_check, "args", 9)  # the discard port: nothing is expected back
    bad = {k.removeprefix("bad."): v for k, v in found.items() if k.startswith("bad.")}
    assert len(bad) == 41
    for name, outcome in bad.items():
        assert outcome.startswith("ArgumentException: "), f"{name}: {outcome}"
    assert bad["intensity_nan"] == "ArgumentException: intensity must be a finite number, got NaN"
    assert bad["intensity_above"] == "ArgumentException: intensity 1.5 is outside the allowed range [0, 1]"
    assert bad["channel_zero"] == "ArgumentException: channel 0 is outside 1..64 (channels count from 1)"
    assert bad["source_17"] == "ArgumentException: source 17 is outside 1..16 (sources count from 1)"
    assert bad["speed_negative"] == "ArgumentException: speed (mm/s) must be >= 0, got -3"
    assert bad["clip_rate_zero"] == "ArgumentException: rate 0 is outside the allowed range [0.05, 20]"
    assert bad["clip_loops_above"] == (
        "ArgumentException: loops 10001 is outside the allowed range [0, 10000] (0 = until stopped)"
    )
    assert bad["preset_null"] == "ArgumentException: preset name must not be null"
    assert found["sent_after_bad"] == "0"
    assert found["sent_after_good"] == "15"  # the good calls each sent one packet
