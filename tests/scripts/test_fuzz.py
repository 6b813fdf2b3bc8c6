"""fuzz/seeds.py: the fuzzers' seeds are valid OSC made from docs/osc.md, the dictionary is libFuzzer's format.

(The fuzzers themselves run in scripts/test.sh: ``scripts/fuzz.sh --seconds 30``.)
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from vibsynth.control.osc.codec import Bundle, MalformedPacket, Message, decode_packet
from vibsynth.control.osc.transport import FramingDetector
from vibsynth.limits import OSC_FAST_ADDRESS_MAX

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fuzz") / "seeds"
    done = subprocess.run([sys.executable, str(ROOT / "fuzz" / "seeds.py"), str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out


def test_the_datagram_seeds_are_the_documented_addresses_as_valid_osc(seeds):
    out = seeds
    packets = [p.read_bytes() for p in sorted((out / "datagram").iterdir())]
    decoded = [decode_packet(p) for p in packets]  # MalformedPacket if a seed were not OSC
    addresses = {m.address for m in decoded if isinstance(m, Message)}
    documented = set(re.findall(r"`(/vibsynth/[a-z/]+) ", (ROOT / "docs" / "osc.md").read_text(encoding="utf-8")))
    assert documented and documented <= addresses
    assert {"/vibsynth/intensity", "/vibsynth/ch/8/texture", "/vibsynth/source/1/pos"} <= addresses
    assert "/" + "a" * (OSC_FAST_ADDRESS_MAX - 1) in addresses  # the table's longest address
    assert any(isinstance(m, Bundle) for m in decoded)
    assert {m.types for m in decoded if isinstance(m, Message)} >= {"", "f", "i", "d", "ff", "s", "dd"}


def test_the_tcp_seeds_are_framed_streams_of_datagram_seeds_and_refused_packets(seeds):
    out = seeds
    datagrams = {p.read_bytes() for p in (out / "datagram").iterdir()}
    framings = set()
    for path in (out / "tcp").iterdir():
        detector = FramingDetector()
        data = path.read_bytes()
        assert data[:2] == b"\x00\x00"  # fuzz_tcp_framing.split_input's header: 64 KiB frames, one read
        frames = detector.feed(data[2:])
        assert frames and not detector.pending
        for frame in set(frames) - datagrams:  # the packets the decoder refuses at its last checks
            with pytest.raises(MalformedPacket, match="UTF-8|char|nested"):
                decode_packet(frame)
        framings.add(detector.framing)
    assert framings == {"slip", "length"}


def test_the_dictionary_holds_the_range_ends_and_their_neighbours(seeds):
    lines = (seeds / "datagram.dict").read_text(encoding="ascii").splitlines()
    assert all(re.fullmatch(r'"(\\x[0-9a-f]{2})+"', line) for line in lines)
    tokens = {bytes.fromhex(line[1:-1].replace("\\x", "")) for line in lines}
    # float32 1.0 and the next float above it; float64 3.5 and the next double above it
    assert {bytes.fromhex("3f800000"), bytes.fromhex("3f800001"), bytes.fromhex("400c000000000001")} <= tokens
