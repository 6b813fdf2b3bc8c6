"""Helpers of the studio tests: a running server on a free port, HTTP and WebSocket clients."""

from __future__ import annotations

import asyncio
import http.client as httpclient
import json
import socket
from collections.abc import Awaitable, Callable
from typing import Any

import aiohttp


def http(
    server: Any,
    method: str,
    path: str,
    *,
    token: str | None = "server",
    headers: dict[str, str] | None = None,
    body: bytes | None = None,
    host: str | None = None,
) -> tuple[int, dict[str, str], bytes]:
    """One request; ``token="server"`` sends the server's token as a Bearer header, None none."""
    conn = httpclient.HTTPConnection("127.0.0.1", server.port, timeout=10)
    sent = dict(headers or {})
    if token is not None:
        sent["Authorization"] = f"Bearer {server.token if token == 'server' else token}"
    if host is not None:
        sent["Host"] = host
    try:
        conn.request(method, path, body=body, headers=sent)
        response = conn.getresponse()
        return response.status, {k.lower(): v for k, v in response.getheaders()}, response.read()
    finally:
        conn.close()


def get_json(server: Any, path: str) -> Any:
    status, _, body = http(server, "GET", path)
    assert status == 200, body
    return json.loads(body)


def origin(server: Any) -> str:
    return f"http://127.0.0.1:{server.port}"


def run(coro: Awaitable[Any]) -> Any:
    return asyncio.run(coro)  # type: ignore[arg-type]


async def connect(
    session: aiohttp.ClientSession, server: Any, *, token: str | None = "server", origin_header: str | None = "own"
) -> aiohttp.ClientWebSocketResponse:
    """A page's WebSocket (token in the query, the studio's own Origin unless told otherwise)."""
    query = "" if token is None else f"?token={server.token if token == 'server' else token}"
    headers = {}
    if origin_header is not None:
        headers["Origin"] = origin(server) if origin_header == "own" else origin_header
    return await session.ws_connect(f"http://127.0.0.1:{server.port}/ws{query}", headers=headers)


async def receive_until(
    ws: aiohttp.ClientWebSocketResponse, predicate: Callable[[dict[str, Any]], bool], timeout: float = 10.0
) -> dict[str, Any]:
    """The first pushed message (batches flattened) for which ``predicate`` holds."""

    async def loop() -> dict[str, Any]:
        while True:
            raw = await ws.receive()
            if raw.type != aiohttp.WSMsgType.TEXT:
                raise AssertionError(f"socket ended: {raw.type} {raw.data!r} {raw.extra!r}")
            data = json.loads(raw.data)
            for message in data["messages"] if data.get("type") == "batch" else [data]:
                if predicate(message):
                    return message

    return await asyncio.wait_for(loop(), timeout)


def raw_request(port: int, head: bytes, timeout: float = 10.0) -> bytes:
    """Send raw bytes (a request head without its body) and read what comes back until the server closes."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        sock.sendall(head)
        chunks = []
        while True:
            try:
                chunk = sock.recv(65536)
            except (ConnectionResetError, TimeoutError):
                break
            if not chunk:
                break
            chunks.append(chunk)
            if b"\r\n\r\n" in b"".join(chunks) and b"Content-Length" in b"".join(chunks):
                data = b"".join(chunks)
                head_end = data.index(b"\r\n\r\n") + 4
                length = int(data.split(b"Content-Length: ")[1].split(b"\r\n")[0])
                if len(data) >= head_end + length:
                    break
        return b"".join(chunks)


def texture_recording(path: Any, psd_file: Any, label: str, *, seconds: float = 3.0, seed: int = 0) -> dict[str, Any]:
    """A WAV (16-bit PCM, 10 kHz) of noise with the spectrum of a HaTT texture model from ../shared.

    The Penn Haptic Texture Toolkit's models are what the dataset holds (no recordings are
    public): the signal is Gaussian noise shaped by the texture's PSD, as the models render.

    Returns
    -------
    expected : dict
        ``balance`` of the model's spectrum (from its band powers, no signal involved), the
        texture ``label``, the row used, and the ``path``.
    """
    import numpy as np

    from vibsynth.dsp.basis import band_powers_from_psd, to_db
    from vibsynth.formats.basis_file import default_basis
    from vibsynth.formats.psd import read_psd_table
    from vibsynth.formats.recordings import write_wav

    table = read_psd_table(psd_file)
    row = next(i for i, name in enumerate(table.labels) if name == label)
    fs, n = 10_000.0, int(seconds * 10_000)
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    log_psd = np.interp(np.log(np.maximum(freqs, 1e-9)), np.log(table.freqs_hz), np.log(table.psd[row]))
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfft(rng.standard_normal(n)) * np.sqrt(np.exp(log_psd))
    signal = np.fft.irfft(spectrum, n)
    signal *= 0.5 / np.max(np.abs(signal))
    write_wav(path, signal, fs, sample_format="pcm16")
    basis = default_basis()
    t1 = basis.scores(to_db(band_powers_from_psd(table.freqs_hz, table.psd[row])))[0]
    return {"label": label, "row": row, "balance": float(basis.balance_from_t1(t1)), "path": path}
