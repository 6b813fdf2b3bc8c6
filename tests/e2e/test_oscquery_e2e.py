"""End to end on the JACK dummy server: 100 OSCQuery clients LISTEN to a knob while 10,000 OSC
messages/s move it; the audio does not collapse (the underflow figures beside a quiet window and
the peers are benchmarks/bench_rt_share.py's), every client keeps receiving the knob's values, and
they end on the last value sent.

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_oscquery_e2e.py -q -s``.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
import time
from pathlib import Path

import aiohttp
import pytest

from tests.e2e.jackutil import REALTIME, assert_no_collapse
from tests.e2e.oscclient import OscClient as Client
from tests.e2e.test_osc_e2e import jack_available, start_serve, stop_serve, unavailable
from vibsynth.control.osc.codec import decode_packet, encode_message

pytestmark = pytest.mark.e2e

CLIENTS = 100
SECONDS = float(os.environ.get("VIBSYNTH_OSCQUERY_LOAD_SECONDS", "5"))
RATE = 10_000
ADDRESS = "/vibsynth/ch/1/intensity"


@pytest.fixture
def jack_oscquery(tmp_path: Path):
    if not jack_available():
        unavailable("no JACK server reachable (run under scripts/with_jack.sh) or JACK-Client missing")
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    proc, port = start_serve(tmp_path, output="sounddevice", env=env, extra_config="studio: {enabled: false}\n")
    deadline = time.monotonic() + 30.0
    lines: list[str] = []
    while not lines and time.monotonic() < deadline:  # the banner follows the OSC server's start
        log = (tmp_path / "serve.log").read_text()
        lines = [line for line in log.splitlines() if line.startswith("oscquery: ")]
        time.sleep(0.1)
    assert lines, log
    url = lines[0].split(" ", 1)[1]
    yield port, int(url.rstrip("/").rsplit(":", 1)[1])
    stop_serve(proc)


class Listeners:
    """``n`` WebSocket clients LISTENing to :data:`ADDRESS` on a loop thread; values received per client."""

    def __init__(self, port: int, n: int) -> None:
        self.port, self.n = port, n
        self.loop = asyncio.new_event_loop()
        self.received = [0] * n
        self.last: list[float | None] = [None] * n
        threading.Thread(target=self.loop.run_forever, daemon=True).start()
        asyncio.run_coroutine_threadsafe(self._open(), self.loop).result(60)

    async def _open(self) -> None:
        self.session = aiohttp.ClientSession()
        self.sockets = []
        for i in range(self.n):
            ws = await self.session.ws_connect(f"http://127.0.0.1:{self.port}/")
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": ADDRESS}))
            self.sockets.append(ws)
            asyncio.ensure_future(self._read(i, ws))

    async def _read(self, i: int, ws) -> None:
        async for msg in ws:
            if msg.type == aiohttp.WSMsgType.BINARY:
                self.received[i] += 1
                self.last[i] = float(decode_packet(msg.data).args[0])

    def close(self) -> None:
        async def shut() -> None:
            for ws in self.sockets:
                await ws.close()
            await self.session.close()

        asyncio.run_coroutine_threadsafe(shut(), self.loop).result(60)
        self.loop.call_soon_threadsafe(self.loop.stop)


def _flood(client: Client, seconds: float) -> int:
    messages = [encode_message(ADDRESS, ((k % 100) / 100.0,), "f") for k in range(100)]
    batch, sent = 10, 0
    period = batch / RATE
    start = next_t = time.perf_counter()
    while next_t < start + seconds:
        for _ in range(batch):
            client.sock.sendto(messages[sent % 100], client.target)
            sent += 1
        next_t += period
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    client.sock.sendto(encode_message(ADDRESS, (0.625,), "f"), client.target)
    return sent + 1


@REALTIME
def test_hundred_listeners_during_a_flood_are_served_and_the_audio_holds(jack_oscquery):
    osc_port, query_port = jack_oscquery
    client = Client(osc_port)
    try:
        before = client.status()["underflows"]
        time.sleep(SECONDS)
        baseline = client.status()["underflows"] - before
        listeners = Listeners(query_port, CLIENTS)
        try:
            time.sleep(0.5)
            start = client.status()
            sent = _flood(client, SECONDS)
            client.request("/vibsynth/sync", 1, expect="/vibsynth/synced", timeout=20.0)
            time.sleep(0.5)  # the last push
            end = client.status()
            received, last = list(listeners.received), list(listeners.last)
        finally:
            listeners.close()
    finally:
        client.close()
    loaded = end["underflows"] - start["underflows"]
    print(
        f"\n{CLIENTS} OSCQuery listeners, {sent} OSC messages in {SECONDS:g} s: underflows {loaded} "
        f"(quiet baseline {baseline} in {SECONDS:g} s); values per client min {min(received)} "
        f"median {sorted(received)[CLIENTS // 2]} max {max(received)}"
    )
    assert end["errors"] == start["errors"]
    assert all(v == pytest.approx(0.625) for v in last)  # everyone ends on the last value sent
    assert min(received) >= 10  # every client kept being served during the flood
    assert max(received) <= SECONDS / 0.005 + 50  # coalesced: at most one push per 5 ms
    assert_no_collapse(loaded, (end["frame"] - start["frame"]) / end["rate"], f"{CLIENTS} listeners and a flood")
