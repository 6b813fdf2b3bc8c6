#!/usr/bin/env python3
"""Write the fuzzers' seed corpus, made from the OSC addresses docs/osc.md documents.

Usage::

    python fuzz/seeds.py OUT   # OUT/datagram/* (an OSC packet each), OUT/tcp/* (a TCP stream each), OUT/datagram.dict

Every address of the form ``/vibsynth/...`` in docs/osc.md (``{n}`` as channels 1 and 8,
``{k}`` as source 1, patterns kept as written) becomes messages with the argument shapes
clients send (none, ``f``, ``i``, ``d``, ``ff``, ``s``), one immediate bundle of them, and the
longest address the fast path's table holds. The TCP seeds are a few of those packets framed
with SLIP and with a length prefix, as one stream. Generated at run time by scripts/fuzz.sh, so
the seeds follow the documentation.
"""

from __future__ import annotations

import hashlib
import math
import re
import struct
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from vibsynth.control.osc.codec import IMMEDIATE, encode_bundle, encode_message  # noqa: E402
from vibsynth.control.osc.transport import length_encode, slip_encode  # noqa: E402
from vibsynth.limits import OSC_FAST_ADDRESS_MAX  # noqa: E402

#: An address in the docs: /vibsynth and parts of address and pattern characters.
ADDRESS = re.compile(r"/vibsynth(?:/[A-Za-z0-9_.{}\[\]*?,!\-]+)*")
#: The argument shapes clients send: (type tags, values).
SHAPES = [("", ()), ("f", (0.5,)), ("i", (1,)), ("d", (0.25,)), ("ff", (0.5, 1.0)), ("s", ("velvet",))]


def doc_addresses(doc: Path = ROOT / "docs" / "osc.md") -> list[str]:
    """The addresses docs/osc.md names, placeholders filled in, in a stable order."""
    found: set[str] = set()
    for raw in ADDRESS.findall(doc.read_text(encoding="utf-8")):
        address = raw.rstrip("/.,")
        if not address or ".." in address:
            continue
        for filled in {address.replace("{n}", "1").replace("{k}", "1"), address.replace("{n}", "8")}:
            found.add(filled)
    return sorted(found)


def datagrams() -> list[bytes]:
    """One packet per address and shape, a bundle of the knob messages, the longest fast address."""
    packets = [encode_message(a, values, tags) for a in doc_addresses() for tags, values in SHAPES]
    knobs = [
        encode_message("/vibsynth/intensity", (0.5,), "f"),
        encode_message("/vibsynth/ch/1/texture", (0.3, -1.0), "ff"),
    ]
    packets.append(encode_bundle(IMMEDIATE, knobs))
    longest = "/" + "a" * (OSC_FAST_ADDRESS_MAX - 1)
    packets += [encode_message(longest, (0.5, 1.0), "ff"), encode_message(longest, (0.5, 1.0), "dd")]
    return packets + every_kind()


def every_kind() -> list[bytes]:
    """What the decoder reads besides the documented shapes: every type tag, an array, nested bundles."""
    tags = "ifsbhtdcSTFNI"
    values = (1, 0.5, "s", b"\x01\x02\x03", 2**40, 7, 0.25, "c", "S", True, False, None, math.inf)
    every = encode_message("/vibsynth/status", values, tags)
    head = encode_message("/vibsynth/texture", (), "")[:-4]  # the address, padded; then the raw tags
    array = head + b",[ff]rm\x00" + struct.pack(">ff", 0.5, 1.0) + b"\x00\x00\x00\xff" * 2
    inner = encode_bundle(IMMEDIATE, [every])
    return [every, array, encode_bundle(IMMEDIATE, [inner, array]), encode_bundle(1 << 32, [])]


def refused() -> list[bytes]:
    """Packets the decoder refuses at its last checks: a non-UTF-8 address, a char beyond Unicode,
    bundles nested too deep."""
    deep = encode_message("/vibsynth/ping", (1,), "i")
    for _ in range(10):
        deep = encode_bundle(IMMEDIATE, [deep])
    return [
        b"/vibsynth/\xff\x00,\x00\x00\x00",
        encode_message("/vibsynth/get", (1,), "i").replace(b",i", b",c")[:-4] + struct.pack(">i", 0x110000),
        deep,
    ]


def streams(packets: list[bytes]) -> list[bytes]:
    """TCP streams: runs of packets framed with SLIP, and with a length prefix."""
    runs = [packets[i : i + 3] for i in range(0, len(packets), 17)] + [every_kind(), refused()]
    return [b"".join(frame(p) for p in run) for run in runs for frame in (slip_encode, length_encode)]


#: The live ranges' ends the fast path compares against (fuzz_datagram.c: intensity [0, 1], balance [-3.5, 3.5]).
RANGE_ENDS = (0.0, 1.0, -3.5, 3.5)


def _around(value: float, fmt: str) -> list[bytes]:
    """``value`` and its neighbours in the last place, encoded as ``fmt`` (">f" float32, ">d" float64)."""
    kind = np.float32 if fmt == ">f" else np.float64
    x = kind(value)
    return [struct.pack(fmt, float(v)) for v in (np.nextafter(x, kind(-np.inf)), x, np.nextafter(x, kind(np.inf)))]


def dictionary() -> list[bytes]:
    """libFuzzer dictionary tokens: the ranges' ends and their neighbours in the last place, specials,
    type tag strings and address parts. A fuzzer cannot see a float comparison, so a range check that
    lets 1.0000001 through is found through these."""
    tokens = []
    for fmt in (">f", ">d"):
        for end in RANGE_ENDS:
            tokens += _around(end, fmt)
        tokens += [struct.pack(fmt, v) for v in (-0.0, math.inf, -math.inf, math.nan, 5e-324 if fmt == ">d" else 1e-45)]
    tokens += [struct.pack(">i", v) for v in (-4, -3, -1, 0, 1, 2, 3, 4, 2**31 - 1, -(2**31))]
    tokens += [b",f\x00\x00", b",i\x00\x00", b",d\x00\x00", b",ff\x00", b",dd\x00", b",fi\x00", b",if\x00", b",id\x00"]
    tokens += [b"/vibsynth", b"/ch/", b"/intensity\x00", b"/balance\x00", b"/texture\x00", b"#bundle\x00"]
    return tokens


def write_dictionary(path: Path, tokens: list[bytes]) -> None:
    """libFuzzer's dictionary format: one quoted token a line, every byte as \\xNN."""
    lines = ['"' + "".join(f"\\x{b:02x}" for b in token) + '"' for token in tokens]
    path.write_text("\n".join(lines) + "\n", encoding="ascii")


#: fuzz_tcp_framing.py's input header: frames up to 64 KiB, the stream in one read (split_input).
TCP_HEADER = b"\x00\x00"


def write(folder: Path, items: list[bytes]) -> int:
    folder.mkdir(parents=True, exist_ok=True)
    for item in items:
        (folder / hashlib.sha1(item).hexdigest()).write_bytes(item)
    return len(items)


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__.strip().splitlines()[0], "\nusage: seeds.py OUT", file=sys.stderr)
        return 2
    out = Path(argv[0])
    packets = datagrams()
    n = write(out / "datagram", packets)
    m = write(out / "tcp", [TCP_HEADER + stream for stream in streams(packets)])
    write_dictionary(out / "datagram.dict", dictionary())
    print(f"seeds: {n} datagrams, {m} TCP streams from docs/osc.md in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
