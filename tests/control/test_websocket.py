"""MaskGuard: follows the client's frame boundaries in any chunking and stops at the first unmasked frame."""

from __future__ import annotations

import numpy as np
import pytest
from aiohttp import WSCloseCode

from tests.control.websocket_frames import client_frame
from vibsynth.control.websocket import MaskGuard, UnmaskedFrame


class Reader:
    """aiohttp's frame reader as the guard sees it: keeps what it is fed."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.eof = False

    def feed_data(self, data: bytes) -> tuple[bool, bytes]:
        self.data += data
        return False, b""

    def feed_eof(self) -> None:
        self.eof = True


class Queue:
    def __init__(self) -> None:
        self.exceptions: list[BaseException] = []

    def set_exception(self, exc: BaseException) -> None:
        self.exceptions.append(exc)


def _chunks(data: bytes, rng: np.random.Generator) -> list[bytes]:
    cuts = sorted(set(rng.integers(0, len(data), size=int(rng.integers(1, 40))).tolist()))
    return [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True) if b > a]


#: Masked frames of every length encoding (7-bit, 16-bit, 64-bit) and opcode kind.
MASKED = [
    client_frame(0x1, b""),
    client_frame(0x1, b"x" * 125),
    client_frame(0x2, bytes(range(256)) * 2, fin=False),
    client_frame(0x0, b"y" * 126),
    client_frame(0x0, b"z" * 70_000),
    client_frame(0x9, b"ping"),
    client_frame(0xA, b""),
]


@pytest.mark.parametrize("seed", range(20))
def test_masked_frames_pass_through_untouched_in_any_chunking(seed):
    rng = np.random.default_rng(seed)
    stream = b"".join(MASKED[int(i)] for i in rng.permutation(len(MASKED)))
    reader, queue = Reader(), Queue()
    guard = MaskGuard(reader, queue)
    for chunk in _chunks(stream, rng):
        assert guard.feed_data(chunk) == (False, b"")
    assert bytes(reader.data) == stream and not queue.exceptions and not guard.refused


@pytest.mark.parametrize("seed", range(20))
def test_the_first_unmasked_frame_is_never_passed_on_and_refuses_the_connection(seed):
    rng = np.random.default_rng(seed)
    before = b"".join(MASKED[int(i)] for i in rng.permutation(len(MASKED))[: int(rng.integers(0, len(MASKED)))])
    bad = client_frame(0x1, b'{"COMMAND": "LISTEN"}' * int(rng.integers(1, 10)), mask=False)
    stream = before + bad + client_frame(0x1, b"after")
    reader, queue = Reader(), Queue()
    guard = MaskGuard(reader, queue)
    results = [guard.feed_data(chunk) for chunk in _chunks(stream, rng)]
    assert guard.refused and (True, b"") in results
    assert all(eof for eof, _ in results[results.index((True, b"")) :])  # and nothing is read after it
    # what the reader got: the masked frames, perhaps the bad frame's first byte (alone, nothing)
    assert bytes(reader.data) in (before, before + bad[:1])
    (exc,) = queue.exceptions
    assert isinstance(exc, UnmaskedFrame) and exc.code == WSCloseCode.PROTOCOL_ERROR


def test_after_a_refusal_nothing_more_is_read_and_eof_reaches_the_reader():
    reader, queue = Reader(), Queue()
    guard = MaskGuard(reader, queue)
    assert guard.feed_data(client_frame(0x1, b"x", mask=False)) == (True, b"")
    assert guard.feed_data(client_frame(0x1, b"y")) == (True, client_frame(0x1, b"y"))
    assert reader.data == b"" and len(queue.exceptions) == 1
    guard.feed_eof()
    assert reader.eof
