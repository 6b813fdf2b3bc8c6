"""A WebSocket endpoint that holds clients to RFC 6455's framing MUSTs (the OSCQuery and studio sockets).

aiohttp's frame reader already closes the connection with 1002 (protocol error) on a reserved
bit set without an extension, a reserved opcode, a control frame over 125 bytes or fragmented,
a continuation that continues nothing, and with 1009 on a message over ``max_msg_size``. It does
not check the mask: a client frame without one was read and acted on (issue 31, finding 7),
while RFC 6455 section 5.1 says "a server MUST close the connection upon receiving a frame that
is not masked". :class:`StrictWebSocketResponse` puts :class:`MaskGuard` in front of aiohttp's
reader: it follows the frame boundaries of the byte stream, passes the bytes through untouched
while every frame is masked, and at the first frame that is not, stops reading (that frame and
what follows are never parsed) and ends the socket with 1002; the handler's ``receive()`` then
gives a :data:`~aiohttp.WSMsgType.ERROR` message whose data is an :class:`UnmaskedFrame`.
"""

from __future__ import annotations

from typing import Any

from aiohttp import WebSocketError, WSCloseCode, web

__all__ = ["UnmaskedFrame", "MaskGuard", "StrictWebSocketResponse", "accept"]


class UnmaskedFrame(WebSocketError):
    """A client sent a frame without a mask (RFC 6455 section 5.1): the connection is closed with 1002."""

    def __init__(self) -> None:
        super().__init__(WSCloseCode.PROTOCOL_ERROR, "client frame not masked (RFC 6455 5.1)")


class MaskGuard:
    """The socket's parser in front of aiohttp's frame reader: refuses the first unmasked frame.

    Parameters
    ----------
    reader : Any
        aiohttp's ``WebSocketReader`` (``feed_data(bytes) -> (eof, tail)``, ``feed_eof()``).
    queue : Any
        Its message queue (``set_exception``): where :class:`UnmaskedFrame` goes.
    """

    def __init__(self, reader: Any, queue: Any) -> None:
        self.reader = reader
        self.queue = queue
        self.refused = False
        self._header = bytearray()  # the bytes read of the current frame's header
        self._payload_left = 0  # payload bytes of the current frame still to pass through

    def _header_size(self) -> int:
        """Bytes of the current header once its first two are known: 2, the length's 2 or 8, the mask's 4."""
        second = self._header[1]
        length = second & 0x7F
        return 2 + (2 if length == 126 else 8 if length == 127 else 0) + (4 if second & 0x80 else 0)

    def _frame_ends(self) -> None:
        """The header is complete: its payload follows."""
        length = self._header[1] & 0x7F
        if length >= 126:
            length = int.from_bytes(self._header[2 : 4 if length == 126 else 10], "big")
        self._payload_left = length
        self._header.clear()

    def feed_data(self, data: bytes | bytearray | memoryview) -> tuple[bool, bytes]:
        """Pass ``data`` on up to the first unmasked frame's header; there, refuse the connection."""
        data = bytes(data)
        if self.refused:
            return True, data
        pos, n = 0, len(data)
        while pos < n:
            if self._payload_left:
                step = min(self._payload_left, n - pos)
                self._payload_left -= step
                pos += step
                continue
            self._header.append(data[pos])
            pos += 1
            if len(self._header) == 2 and not self._header[1] & 0x80:
                # the frame's first header byte may already have reached the reader: alone it is nothing
                forwarded = self.reader.feed_data(data[: pos - 2] if pos >= 2 else b"")
                self.refused = True
                if not forwarded[0]:
                    self.queue.set_exception(UnmaskedFrame())
                return True, b""
            if len(self._header) >= 2 and len(self._header) == self._header_size():
                self._frame_ends()
        eof, tail = self.reader.feed_data(data)
        self.refused = bool(eof)
        return eof, tail

    def feed_eof(self) -> None:
        """The peer closed its side."""
        self.reader.feed_eof()


class _GuardedProtocol:
    """The request's protocol as aiohttp's ``_post_start`` sees it: ``set_parser`` installs a :class:`MaskGuard`."""

    def __init__(self, protocol: Any, response: StrictWebSocketResponse) -> None:
        self._protocol = protocol
        self._response = response

    def set_parser(self, parser: Any, *args: Any, **kwargs: Any) -> None:
        guard = MaskGuard(parser, self._response._reader)
        self._response.mask_guard = guard
        self._protocol.set_parser(guard, *args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._protocol, name)


class _GuardedRequest:
    """The request as aiohttp's ``_post_start`` sees it (its protocol is :class:`_GuardedProtocol`)."""

    def __init__(self, request: web.BaseRequest, response: StrictWebSocketResponse) -> None:
        self._request = request
        self.protocol = _GuardedProtocol(request.protocol, response)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._request, name)


class StrictWebSocketResponse(web.WebSocketResponse):
    """aiohttp's server WebSocket, closing with 1002 on a client frame without a mask (:class:`MaskGuard`).

    Data that arrived with the handshake is read through the guard too (``set_parser`` feeds it).
    """

    mask_guard: MaskGuard | None = None

    def _post_start(self, request: web.BaseRequest, *args: Any, **kwargs: Any) -> None:
        super()._post_start(_GuardedRequest(request, self), *args, **kwargs)  # type: ignore[arg-type]
        if self.mask_guard is None:  # aiohttp changed how it installs its reader: fail loudly, not open
            raise RuntimeError("the WebSocket mask check could not be installed (aiohttp changed)")


async def accept(ws: web.WebSocketResponse, request: web.Request) -> bool:
    """Answer the upgrade request; False when the client was gone before the answer was written.

    A client that sends its upgrade request and resets the connection makes ``prepare`` raise a
    ConnectionError (aiohttp's ClientConnectionResetError is one): there is nobody to answer, it
    is no bad input and no fault of the server, so the caller just ends the request quietly
    (aiohttp logged it as an error with a traceback).
    """
    try:
        await ws.prepare(request)
    except ConnectionError:
        return False
    return True
