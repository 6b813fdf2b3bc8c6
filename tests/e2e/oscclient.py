"""One UDP OSC client for the end-to-end tests (our own codec; liblo is the independent one)."""

from __future__ import annotations

import socket

from vibsynth.control.osc.codec import Message, decode_packet, encode_message

__all__ = ["OscClient", "free_udp_port"]


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class OscClient:
    """A UDP socket talking to a served port (replies come back to it unless reply_port is set)."""

    def __init__(self, port: int) -> None:
        self.target = ("127.0.0.1", port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)

    def send(self, address: str, *args: object, types: str | None = None) -> None:
        self.sock.sendto(encode_message(address, args, types), self.target)

    def request(
        self, address: str, *args: object, expect: str, timeout: float = 5.0, types: str | None = None
    ) -> Message:
        """Send, then return the first reply whose address is ``expect`` (socket.timeout if none)."""
        self.send(address, *args, types=types)
        self.sock.settimeout(timeout)
        while True:
            msg = decode_packet(self.sock.recvfrom(65536)[0])
            if msg.address == expect:
                return msg

    def status(self) -> dict:
        msg = self.request("/vibsynth/status", expect="/vibsynth/status.reply")
        return dict(zip(msg.args[::2], msg.args[1::2]))

    def texture(self) -> tuple[float, float]:
        return tuple(self.request("/vibsynth/get", "texture", expect="/vibsynth/texture").args)  # type: ignore[return-value]

    def close(self) -> None:
        self.sock.close()
