#!/usr/bin/env python3
"""OSCQuery costs and latency: an OSC knob move -> the value at a LISTENing WebSocket client.

    python benchmarks/bench_oscquery.py [--trials 300] [--clients 1 100]

The service runs in this process (engine on the null output, Controller, OSC server and the
OSCQuery server wired as ``vibsynth serve`` wires them). The listeners are WebSocket clients
in one asyncio loop of this process, each LISTENing to ``/vibsynth/ch/1/intensity``.

* **OSC -> listener**: ``/vibsynth/ch/1/intensity v`` sent over UDP (timestamped before the
  send); the latency is when the *last* listener received the binary OSC message with ``v``
  (one clock: ``time.perf_counter`` of this process). It includes the OSC receive loop, the
  Controller's event, the push coalescing interval (5 ms) and the WebSocket.
* **studio -> listener**: the same move sent as the studio page sends it (its WebSocket, with
  the token), timestamped before the send.
* **controller -> listener**: the same through ``Controller.set_knob`` (what MIDI, clips and
  follow do).
* **tree**: ``GET /`` (the whole tree with live values) size and time, 1 and 8 channels.

Trials are 30 ms apart (no coalescing between them). Prints a table and writes JSON to
benchmarks/results/oscquery.json.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import platform
import socket
import sys
import threading
import time
import urllib.request
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import aiohttp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from latency_stats import summary_ms  # noqa: E402 - benchmarks/, beside this script

from vibsynth.control.osc.codec import decode_packet, encode_message  # noqa: E402

GAP_S = 0.03
ADDRESS = "/vibsynth/ch/1/intensity"


def start_service(channels: int) -> SimpleNamespace:
    """Engine (null output), Controller, OSC server and OSCQuery, wired like ``vibsynth serve``."""
    from vibsynth.app.service import build_engine, open_output
    from vibsynth.control.controller import Controller
    from vibsynth.control.osc import adapter as osc_adapter
    from vibsynth.control.oscquery import adapter as oscquery_adapter
    from vibsynth.control.studio import adapter as studio_adapter
    from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir
    from vibsynth.settings.config import load_config
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    overrides = {"audio.backend": "null", "audio.channels": channels, "osc.port": 0}
    settings = load_config(overrides=overrides, env={}, user_file=False).settings
    engine = build_engine(settings)
    controller = Controller.for_knobs(engine, settings.knobs)
    out = open_output(settings.audio, engine, False)
    controller.output = out  # type: ignore[attr-defined]
    osc = osc_adapter.create(settings, None, controller)
    osc.start()
    presets = PresetLibrary(shipped_presets_dir(), None)  # serve's libraries: their entries are nodes too
    clips = ClipLibrary(shipped_clips_dir(), None)
    query = oscquery_adapter.create(
        settings, SimpleNamespace(oscquery_port=0), controller, osc, presets=presets, clips=clips
    )
    query.start()
    args = SimpleNamespace(no_studio=False, studio_port=0, studio_token=None)
    studio = studio_adapter.create(settings, args, controller, None, servers=[osc])
    studio.start()
    out.start()
    return SimpleNamespace(engine=engine, controller=controller, output=out, osc=osc, query=query, studio=studio)


def stop_service(service: SimpleNamespace) -> None:
    service.studio.stop()
    service.query.stop()
    service.osc.stop()
    service.output.stop()


class StudioPage:
    """A studio WebSocket (as the page's), on its own loop thread: moves the intensity knob."""

    def __init__(self, studio: Any) -> None:
        self.loop = asyncio.new_event_loop()
        threading.Thread(target=self.loop.run_forever, daemon=True).start()
        origin = f"http://127.0.0.1:{studio.port}"
        headers = {"Authorization": f"Bearer {studio.token}", "Origin": origin}

        async def open_() -> None:
            self.session = aiohttp.ClientSession()
            self.ws = await self.session.ws_connect(f"{origin}/ws", headers=headers)

        asyncio.run_coroutine_threadsafe(open_(), self.loop).result(30)

    def move(self, value: float) -> None:
        message = json.dumps({"type": "knob", "channel": 1, "name": "intensity", "value": value})
        asyncio.run_coroutine_threadsafe(self.ws.send_str(message), self.loop).result(5)

    def close(self) -> None:
        async def shut() -> None:
            await self.ws.close()
            await self.session.close()

        asyncio.run_coroutine_threadsafe(shut(), self.loop).result(30)
        self.loop.call_soon_threadsafe(self.loop.stop)


class Listeners:
    """``n`` WebSocket clients LISTENing to :data:`ADDRESS`, on their own loop thread."""

    def __init__(self, port: int, n: int) -> None:
        self.port, self.n = port, n
        self.loop = asyncio.new_event_loop()
        self.arrivals: dict[float, list[float]] = {}
        self.lock = threading.Lock()
        self.ready = threading.Event()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        asyncio.run_coroutine_threadsafe(self._open(), self.loop).result(30)

    async def _open(self) -> None:
        self.session = aiohttp.ClientSession()
        self.sockets = []
        for _ in range(self.n):
            ws = await self.session.ws_connect(f"http://127.0.0.1:{self.port}/")
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": ADDRESS}))
            self.sockets.append(ws)
            asyncio.ensure_future(self._read(ws))

    async def _read(self, ws: Any) -> None:
        async for msg in ws:
            if msg.type == aiohttp.WSMsgType.BINARY:
                now = time.perf_counter()
                value = round(float(decode_packet(msg.data).args[0]), 4)
                with self.lock:
                    self.arrivals.setdefault(value, []).append(now)

    def wait_all(self, value: float, timeout: float = 2.0) -> float | None:
        """When the last of the n clients received ``value`` (None: not all within the timeout)."""
        deadline = time.monotonic() + timeout
        key = round(value, 4)
        while time.monotonic() < deadline:
            with self.lock:
                got = self.arrivals.get(key, [])
                if len(got) >= self.n:
                    return max(got[: self.n])
            time.sleep(0.0002)
        return None

    def close(self) -> None:
        async def shut() -> None:
            for ws in self.sockets:
                await ws.close()
            await self.session.close()

        asyncio.run_coroutine_threadsafe(shut(), self.loop).result(30)
        self.loop.call_soon_threadsafe(self.loop.stop)


def latency(service: SimpleNamespace, clients: int, trials: int, via: str) -> dict[str, float]:
    listeners = Listeners(service.query.server.port, clients)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = ("127.0.0.1", service.osc.port)
    page = StudioPage(service.studio) if via == "studio" else None
    results, lost = [], 0
    try:
        time.sleep(0.3)
        for k in range(trials):
            value = round(0.1 + (k % 800) * 0.001, 4)
            sent = time.perf_counter()
            if via == "osc":
                sock.sendto(encode_message(ADDRESS, (value,), "f"), target)
            elif page is not None:
                page.move(value)
            else:
                service.controller.set_knob("intensity", value, channels=(0,), source="studio")
            arrived = listeners.wait_all(value)
            if arrived is None:
                lost += 1
            else:
                results.append((arrived - sent) * 1000.0)
            time.sleep(GAP_S)
    finally:
        sock.close()
        listeners.close()
        if page is not None:
            page.close()
    return {**summary_ms(results), "lost": lost, "clients": clients, "via": via}


def tree_cost(service: SimpleNamespace, rounds: int = 30) -> dict[str, float]:
    url = f"http://127.0.0.1:{service.query.server.port}/"
    times, size = [], 0
    for _ in range(rounds):
        start = time.perf_counter()
        with urllib.request.urlopen(url, timeout=5) as response:
            size = len(response.read())
        times.append((time.perf_counter() - start) * 1000.0)
    return {**summary_ms(times), "bytes": size, "nodes": len(service.query.tree.nodes)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 100])
    args = parser.parse_args(argv)
    rows: list[dict[str, Any]] = []
    trees: dict[str, Any] = {}
    for channels in (1, 8):
        service = start_service(channels)
        try:
            trees[f"{channels}ch"] = tree_cost(service)
            if channels == 1:
                for clients in args.clients:
                    for via in ("osc", "studio", "controller"):
                        rows.append(latency(service, clients, args.trials, via))
        finally:
            stop_service(service)
    print(f"{'path':<12} {'clients':>7} {'n':>5} {'median ms':>10} {'p99 ms':>8} {'max ms':>8} {'lost':>5}")
    for r in rows:
        print(
            f"{r['via']:<12} {r['clients']:>7} {r['n']:>5} {r['median_ms']:>10.2f} {r['p99_ms']:>8.2f} "
            f"{r['max_ms']:>8.2f} {r['lost']:>5}"
        )
    print(f"\n{'GET /':<12} {'nodes':>7} {'bytes':>8} {'median ms':>10} {'p99 ms':>8}")
    for name, t in trees.items():
        print(f"{name:<12} {t['nodes']:>7} {t['bytes']:>8} {t['median_ms']:>10.2f} {t['p99_ms']:>8.2f}")
    result = {
        "benchmark": "oscquery",
        "machine": {"python": platform.python_version(), "cpu": platform.processor() or platform.machine()},
        "latency": rows,
        "tree": trees,
    }
    out = ROOT / "benchmarks" / "results" / "oscquery.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
