"""Raw WebSocket bytes for the framing tests of the OSCQuery and studio sockets (RFC 6455)."""

from __future__ import annotations

import base64
import os
import socket
import struct

#: The fixed masking key of :func:`client_frame`.
KEY = b"\x5a\x17\xc3\x99"


def client_frame(opcode: int, payload: bytes, *, fin: bool = True, mask: bool = True, rsv: int = 0) -> bytes:
    """One client frame (``rsv``: the three reserved bits, RSV1 = 4); masked unless ``mask`` is false."""
    n = len(payload)
    size = bytes([n]) if n < 126 else b"\x7e" + struct.pack(">H", n) if n < 65536 else b"\x7f" + struct.pack(">Q", n)
    head = bytes([(0x80 if fin else 0) | rsv << 4 | opcode])
    if not mask:
        return head + size + payload
    masked = bytes(b ^ KEY[i % 4] for i, b in enumerate(payload))
    return head + bytes([size[0] | 0x80]) + size[1:] + KEY + masked


def handshake(port: int, target: str = "/", origin: str | None = None) -> bytes:
    """The client's upgrade request."""
    key = base64.b64encode(os.urandom(16)).decode()
    extra = "" if origin is None else f"Origin: {origin}\r\n"
    return (
        f"GET {target} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n{extra}\r\n"
    ).encode()


def read_upgrade(sock: socket.socket) -> bytes:
    """Read the server's answer to :func:`handshake`, check it is 101; what followed it."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        assert chunk, f"no handshake answer: {data!r}"
        data += chunk
    status, rest = data.split(b"\r\n\r\n", 1)
    assert b" 101 " in status.split(b"\r\n", 1)[0], status
    return rest


def server_frames(sock: socket.socket, upgraded: bytes | None = None) -> list[tuple[int, bytes]]:
    """The server's frames ``(opcode, payload)`` up to its close frame or the end of the stream.

    ``upgraded``: the bytes :func:`read_upgrade` returned (else the 101 is read and checked first).
    """
    data = read_upgrade(sock) if upgraded is None else upgraded
    frames: list[tuple[int, bytes]] = []
    while True:
        while len(data) >= 2:
            n, at = data[1] & 0x7F, 2
            if n >= 126:
                at = 4 if n == 126 else 10
                if len(data) < at:
                    break
                n = int.from_bytes(data[2:at], "big")
            if len(data) < at + n:
                break
            frames.append((data[0] & 0x0F, data[at : at + n]))
            data = data[at + n :]
            if frames[-1][0] == 0x8:
                return frames
        chunk = sock.recv(65536)
        if not chunk:
            return frames
        data += chunk


def close_code(frames: list[tuple[int, bytes]]) -> int | None:
    """The status code of the last frame if it is a close frame."""
    if not frames or frames[-1][0] != 0x8 or len(frames[-1][1]) < 2:
        return None
    return int.from_bytes(frames[-1][1][:2], "big")
