#!/usr/bin/env python3
"""Atheris (libFuzzer for Python) harness of the OSC/TCP framing (vibsynth/control/osc/transport.py).

Each input is a TCP byte stream as a client sends it, after a header saying how large a frame may
be and where the receive thread's reads cut it (:func:`split_input`). It goes through
:class:`~vibsynth.control.osc.transport.FramingDetector` (SLIP or length-prefixed, told by the
first byte), and each frame through :func:`~vibsynth.control.osc.codec.decode_packet`, as
``TcpTransport`` does. Checked, besides "no exception but MalformedPacket":

* the frames, the oversized count and ``pending`` do not depend on how the reads cut the stream;
* they are what a plain reference decoder of RFC 1055 SLIP / 32-bit length prefixes reads;
* no frame is empty or longer than the limit, and each re-framed with the connection's
  encoder decodes to itself.

Run by scripts/fuzz.sh (``.venv/bin/python fuzz/fuzz_tcp_framing.py [libFuzzer options] CORPUS...``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import atheris

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# Instrumented (coverage for libFuzzer): the codec and the transport, not what the transport imports
# (atheris instruments whole top-level packages, so the order of the imports decides).
with atheris.instrument_imports(include=["vibsynth"]):
    from vibsynth.control.osc.codec import MalformedPacket, decode_packet
import vibsynth.control.osc.fast  # noqa: E402,F401
import vibsynth.settings.allow_list  # noqa: E402,F401
import vibsynth.settings.models_config  # noqa: E402,F401

with atheris.instrument_imports(include=["vibsynth"]):
    from vibsynth.control.osc.transport import FramingDetector

END, ESC, ESC_END, ESC_ESC = 0xC0, 0xDB, 0xDC, 0xDD


def reference_slip(stream: bytes, max_frame: int) -> tuple[list[bytes], int, bool]:
    """RFC 1055 read plainly: frames between ENDs, ESC ESC_END/ESC_ESC unescaped (ESC x: x), too long dropped."""
    frames, oversized = [], 0
    segments = stream.split(bytes([END]))  # the last one is not ended (yet)
    for k, raw in enumerate(segments):
        body, i = bytearray(), 0
        while i < len(raw):
            byte = raw[i]
            if byte == ESC:
                if i + 1 == len(raw):
                    break  # an ESC right before END (or the stream's end so far) escapes nothing
                nxt = raw[i + 1]
                byte = END if nxt == ESC_END else ESC if nxt == ESC_ESC else nxt
                i += 1
            body.append(byte)
            i += 1
        if len(body) > max_frame:
            oversized += 1
        elif body and k < len(segments) - 1:
            frames.append(bytes(body))
    return frames, oversized, bool(segments[-1])


def reference_length(stream: bytes, max_frame: int) -> tuple[list[bytes], int, bool]:
    """32-bit big-endian lengths read plainly: a frame over the limit is skipped, a zero length is nothing."""
    frames, oversized, i = [], 0, 0
    while len(stream) - i >= 4:
        size = int.from_bytes(stream[i : i + 4], "big")
        if size > max_frame:
            oversized += 1
        elif len(stream) - i - 4 < size:
            break
        elif size:
            frames.append(stream[i + 4 : i + 4 + size])
        i += 4 + size
    return frames, oversized, i != len(stream)


def feed(stream: bytes, cuts: list[int], max_frame: int) -> tuple[FramingDetector, list[bytes]]:
    detector = FramingDetector(max_frame)
    frames: list[bytes] = []
    start = 0
    for end in [*cuts, len(stream)]:
        frames += detector.feed(stream[start:end])
        start = end
    return detector, frames


def split_input(data: bytes) -> tuple[int, list[int], bytes]:
    """An input is ``LIMIT NCUTS CUT... STREAM``: LIMIT < 128 means frames up to 64 KiB (the server's),
    else up to 1 + LIMIT % 96 bytes; NCUTS % 9 cut positions of 2 bytes each (big-endian, modulo the
    stream's length + 1) say where the receive thread's reads end; the rest is the TCP stream.
    fuzz/seeds.py writes its streams after ``00 00``."""
    if len(data) < 2:
        return 65536, [], b""
    max_frame = 65536 if data[0] < 128 else 1 + data[0] % 96
    ncuts = min(data[1] % 9, (len(data) - 2) // 2)
    stream = data[2 + 2 * ncuts :]
    cuts = sorted(int.from_bytes(data[2 + 2 * i : 4 + 2 * i], "big") % (len(stream) + 1) for i in range(ncuts))
    return max_frame, cuts, stream


def check(data: bytes) -> None:
    max_frame, cuts, stream = split_input(data)

    whole, frames = feed(stream, [], max_frame)
    cut, cut_frames = feed(stream, cuts, max_frame)
    # a read per byte (a slow link): every state of the decoders sees a chunk boundary (long streams: a read per 7)
    bytewise, byte_frames = feed(stream, list(range(1, len(stream), 1 if len(stream) <= 128 else 7)), max_frame)
    if not cut_frames == byte_frames == frames:
        raise AssertionError(
            f"frames depend on how the reads cut the stream: {frames!r} {cut_frames!r} {byte_frames!r}"
        )
    if (
        not whole.oversized == cut.oversized == bytewise.oversized
        or not whole.pending == cut.pending == bytewise.pending
    ):
        raise AssertionError("the oversized count or pending depends on how the reads cut the stream")
    if stream:
        reference = reference_slip if whole.framing == "slip" else reference_length
        want = reference(stream, max_frame)
        if (frames, whole.oversized, whole.pending) != want:
            raise AssertionError(f"{whole.framing}: {(frames, whole.oversized, whole.pending)!r} != reference {want!r}")
    for frame in frames:
        if not 0 < len(frame) <= max_frame:
            raise AssertionError(f"a frame of {len(frame)} bytes (limit {max_frame})")
        again = FramingDetector(max_frame)
        if again.feed(whole.encode(frame)) != [frame]:
            raise AssertionError("a frame re-framed with the connection's encoder does not decode to itself")
        try:
            decode_packet(frame)
        except MalformedPacket:
            pass


def main() -> None:
    atheris.Setup(sys.argv, check)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
