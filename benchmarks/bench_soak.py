#!/usr/bin/env python3
"""Soak (issue 31): ``vibsynth serve`` for ``--minutes`` under mixed load; does anything grow?

    python benchmarks/bench_soak.py [--minutes 30] [--output jack|null]

``--output jack`` (the default) starts a private JACK server on the dummy driver with 16
playback ports (``jackd -n bench-soak -R -d dummy -r 48000 -p 128 -P 16``, without ``-R`` when
real-time scheduling is refused; benchmarks/bench_peers.py's ``JackServer``) and serves 16
channels through PortAudio on it; ``--output null`` serves on the null output (no JACK, the test's
setting). serve has TCP OSC on, OSCQuery on a free port (no mDNS: every byte goes to 127.0.0.1),
the studio with a known token, a private user preset folder watched for hot reload, and Follow
on a sound file (``follow.device``): a long FLAC made at start from the desktop sound theme's
``.oga`` sounds (Debian's sound-theme-freedesktop), one after the other, so it lasts the run.

The load, while a load window runs:

* **OSC flood**: 10,000 messages/s (``--rate``) in 1 ms bursts (10 messages), ``intensity`` and
  ``balance`` of channel 1 alternating, from a child process (its own interpreter: the rate does
  not depend on this process' threads);
* **clips**: every 0.25 s the next channel (1..16 in turn) is retriggered with a shipped clip
  (``/vibsynth/ch/{n}/play NAME 1 1 1``), so each channel is retriggered every 4 s;
* **Follow** of the file on every channel (a clip beats follow while it plays; follow takes the
  channel back when the clip ends);
* **100 OSCQuery listeners**: WebSocket clients, each LISTENing to the intensity or balance of a
  channel (listener k: channel k mod 16 + 1);
* **5 studio pages**, as clients that do what the page's script does (not browsers: five
  Chromium tabs would take a core of this 2-core VM): load the page with ``?token=`` (the cookie),
  its scripts and style sheet, open ``/ws`` with the cookie, watch a channel, move its intensity
  slider once a second and fetch ``/api/state``, ``/api/presets``, ``/api/status`` and
  ``/api/follow`` every 10 s (what the tabs fetch);
* **a preset hot reload every 10 s**: ``soak.yaml`` in the user preset folder replaced atomically
  (write a temporary file, ``os.replace``) with a new intensity, and the reload checked through
  ``/api/presets`` 2 s later;
* **a client that connects and vanishes every 3 s**, in turn: a TCP OSC client that subscribes
  (``/notify 1``) and pings, an OSCQuery WebSocket that LISTENs, a studio WebSocket that gets its
  hello; each then resets the connection (``SO_LINGER`` 0: an RST, no close handshake).

Quiet windows (``--quiet-seconds``, 30 s) have no load at all (the flood, clips, reloads, page
moves, page fetches and vanishing clients pause; listeners and pages stay connected, Follow goes
on): one before the load, one every ``--quiet-every`` seconds (300) and one at the end. The
underflows in them are the machine's own noise (the JACK dummy driver wakes late on this VM).

Every ``--sample-seconds`` (10) it records serve's RSS (``/proc/PID/status`` VmRSS), open files
(``/proc/PID/fd``), threads (``/proc/PID/task``), CPU time and ``/status`` (underflows, errors,
malformed, packets, oscquery clients), JACK's xruns (a client here counting xrun callbacks) and
the window. At the end: messages sent (every OSC packet this benchmark sent, UDP and TCP) vs the
packets serve counted, underflows per minute quiet vs loaded, errors, and the growth of memory,
files and threads: the slope of a least-squares line through the samples after the first
minute, per hour, and their range. Prints a table and writes JSON to
benchmarks/results/soak.json.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import multiprocessing as mp
import os
import re
import secrets
import socket
import struct
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_osc import write_json  # noqa: E402
from bench_peers import JackServer, Monitor, machine_info, proc_cpu_seconds, stop_all  # noqa: E402

from tests.e2e.oscclient import OscClient  # noqa: E402
from tests.e2e.test_osc_e2e import start_serve, stop_serve  # noqa: E402
from vibsynth.control.osc.codec import Bundle, decode_packet, encode_message  # noqa: E402

CHANNELS = 16
CLIPS = ("rain", "heartbeat", "gravel-steps", "zipper", "impact")
LISTENERS = 100
PAGES = 5
CLIP_EVERY_S = 0.25
PAGE_MOVE_EVERY_S = 1.0
PAGE_FETCH_EVERY_S = 10.0
RELOAD_EVERY_S = 10.0
RELOAD_CHECK_AFTER_S = 2.0
VANISH_EVERY_S = 3.0
VANISH_KINDS = ("tcp-osc", "oscquery-ws", "studio-ws")
WARMUP_S = 60.0  # growth is measured after the first minute
SOUNDS = Path("/usr/share/sounds/freedesktop/stereo")
PAGE_FETCHES = ("/api/state", "/api/presets", "/api/status", "/api/follow")


# ------------------------------------------------------------------ the follow file
def follow_file(folder: Path, seconds: float) -> tuple[Path, list[str]]:
    """A mono FLAC of the desktop sound theme's sounds one after the other, ``seconds`` long."""
    import soundfile as sf

    sounds = sorted(SOUNDS.glob("*.oga"))
    if not sounds:
        raise RuntimeError(f"no .oga sounds in {SOUNDS} (Debian package sound-theme-freedesktop)")
    rate = 48000
    pieces: list[np.ndarray] = []
    for path in sounds:
        data, fs = sf.read(path, dtype="float32", always_2d=True)
        if fs != rate:  # the theme is 44.1 or 48 kHz: a linear resample is enough for a follow input
            t = np.arange(int(len(data) * rate / fs)) / rate
            data = np.interp(t, np.arange(len(data)) / fs, data.mean(axis=1))[:, None].astype(np.float32)
        pieces.append(data.mean(axis=1))
        pieces.append(np.zeros(rate // 2, np.float32))
    one_pass = np.concatenate(pieces)
    passes = int(np.ceil(seconds * rate / one_pass.size))
    out = folder / "follow-soak.flac"
    with sf.SoundFile(out, "w", samplerate=rate, channels=1, subtype="PCM_16", format="FLAC") as fh:
        for _ in range(passes):
            fh.write(one_pass)
    return out, [p.name for p in sounds]


# ------------------------------------------------------------------ counted OSC
class Counted:
    """OSC packets this benchmark sent to serve (every thread), to compare with serve's ``packets``."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.sent = 0

    def add(self, n: int = 1) -> None:
        with self._lock:
            self.sent += n


class CountedClient(OscClient):
    """An OSC UDP client that counts what it sends."""

    def __init__(self, port: int, counted: Counted) -> None:
        super().__init__(port)
        self.counted = counted
        self.lock = threading.Lock()
        self.timeouts = 0

    def send(self, address: str, *args: object, types: str | None = None) -> None:
        self.counted.add()
        super().send(address, *args, types=types)

    def status(self) -> dict:
        """serve's /status; a reply later than 5 s is asked again (counted in ``timeouts``), 6 times at most."""
        with self.lock:
            for _ in range(6):
                try:
                    return super().status()
                except TimeoutError:
                    self.timeouts += 1
            raise TimeoutError("serve did not answer /status in 30 s")


def flood(port: int, rate: int, running: Any, stop: Any, sent: Any) -> None:
    """The OSC flood (a child process): ``rate`` messages/s in 1 ms bursts while ``running`` is set."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = ("127.0.0.1", port)
    messages = [
        encode_message(f"/vibsynth/ch/1/{'intensity' if k % 2 else 'balance'}", ((k % 100) / 100.0,), "f")
        for k in range(200)
    ]
    per_ms = max(1, rate // 1000)
    count = 0
    while not stop.is_set():
        if not running.wait(0.1):
            continue
        start = time.perf_counter()
        next_t = start
        while running.is_set() and not stop.is_set():
            for _ in range(per_ms):
                sock.sendto(messages[count % 200], target)
                count += 1
            sent.value = count
            next_t += per_ms / rate
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.5:  # fell behind (the machine was busy): no catch-up burst
                next_t = time.perf_counter()
    sock.close()


# ------------------------------------------------------------------ raw sockets that vanish
def _reset(sock: socket.socket) -> None:
    """Close with an RST (SO_LINGER 0): the peer sees the connection vanish, no close handshake."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


def _ws_handshake(port: int, path: str, headers: dict[str, str]) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        f"GET {path} HTTP/1.1",
        f"Host: 127.0.0.1:{port}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
        *(f"{k}: {v}" for k, v in headers.items()),
    ]
    sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
    answer = b""
    while b"\r\n\r\n" not in answer:
        chunk = sock.recv(4096)
        if not chunk:
            raise ConnectionError("closed during the WebSocket handshake")
        answer += chunk
    if not answer.startswith(b"HTTP/1.1 101"):
        _reset(sock)
        raise ConnectionError(answer.split(b"\r\n", 1)[0].decode(errors="replace"))
    return sock


def _ws_text(sock: socket.socket, text: str) -> None:
    """Send one masked text frame (a client's)."""
    payload = text.encode()
    mask = os.urandom(4)
    size = len(payload)
    head = bytes([0x81]) + (bytes([0x80 | size]) if size < 126 else bytes([0x80 | 126]) + struct.pack(">H", size))
    sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))


def _addresses(packet: Any) -> list[str]:
    """The addresses of a decoded packet's messages (a bundle's, recursively)."""
    if isinstance(packet, Bundle):
        return [a for element in packet.elements for a in _addresses(element)]
    return [packet.address]


def vanish_tcp_osc(port: int, counted: Counted) -> None:
    """Subscribe (/notify 1) and ping over TCP (length-prefixed), read the pong, then vanish."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    try:
        for packet in (encode_message("/vibsynth/notify", (1,), "i"), encode_message("/vibsynth/ping", (7,), "i")):
            sock.sendall(struct.pack(">i", len(packet)) + packet)
            counted.add()
        buffer = b""
        while True:
            while len(buffer) >= 4 and len(buffer) >= 4 + struct.unpack(">i", buffer[:4])[0]:
                size = struct.unpack(">i", buffer[:4])[0]
                packet, buffer = decode_packet(buffer[4 : 4 + size]), buffer[4 + size :]
                if "/vibsynth/pong" in _addresses(packet):  # /notify pushes come as bundles
                    return
            chunk = sock.recv(65536)
            if not chunk:
                raise ConnectionError("serve closed the TCP connection before /pong")
            buffer += chunk
    finally:
        _reset(sock)


def vanish_oscquery(port: int) -> None:
    """An OSCQuery WebSocket that LISTENs, then vanishes."""
    sock = _ws_handshake(port, "/", {})
    _ws_text(sock, json.dumps({"COMMAND": "LISTEN", "DATA": "/vibsynth/ch/1/intensity"}))
    time.sleep(0.2)
    _reset(sock)


def vanish_studio(port: int, token: str) -> None:
    """A studio WebSocket (the token as a Bearer header) that reads its hello, then vanishes."""
    origin = f"http://127.0.0.1:{port}"
    sock = _ws_handshake(port, "/ws", {"Authorization": f"Bearer {token}", "Origin": origin})
    sock.settimeout(5)
    if not sock.recv(65536):
        raise ConnectionError("no hello from the studio")
    _reset(sock)


# ------------------------------------------------------------------ WebSocket clients (one asyncio loop)
@dataclass
class Clients:
    """The OSCQuery listeners and the studio pages, on an asyncio loop in a thread of this process."""

    oscquery_port: int
    studio_base: str
    studio_url: str
    load: threading.Event
    stop: threading.Event
    errors: list[str]
    listener_pushes: list[int] = field(default_factory=lambda: [0] * LISTENERS)
    page_messages: list[int] = field(default_factory=lambda: [0] * PAGES)
    page_moves: int = 0
    page_fetches: int = 0
    page_bytes_loaded: int = 0
    disconnects: int = 0

    def run(self, ready: threading.Event) -> None:
        asyncio.run(self._main(ready))

    async def _main(self, ready: threading.Event) -> None:
        import aiohttp

        listen_session = aiohttp.ClientSession()
        sockets = []
        readers = []
        for k in range(LISTENERS):
            ws = await listen_session.ws_connect(f"http://127.0.0.1:{self.oscquery_port}/")
            knob = "intensity" if k % 2 == 0 else "balance"
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": f"/vibsynth/ch/{k % CHANNELS + 1}/{knob}"}))
            sockets.append(ws)
            readers.append(asyncio.ensure_future(self._read(ws, self.listener_pushes, k, "listener")))
        pages = [asyncio.ensure_future(self._page(k)) for k in range(PAGES)]
        await asyncio.sleep(1.0)
        ready.set()
        while not self.stop.is_set():
            await asyncio.sleep(0.2)
        for ws in sockets:
            await ws.close()
        await listen_session.close()
        await asyncio.gather(*pages, *readers, return_exceptions=True)

    async def _read(self, ws: Any, counts: list[int], k: int, what: str) -> None:
        """Count the messages a client gets (binary OSC for a listener, JSON text for a page) until it closes."""
        import aiohttp

        wanted = aiohttp.WSMsgType.BINARY if what == "listener" else aiohttp.WSMsgType.TEXT
        async for msg in ws:
            if msg.type == wanted:
                counts[k] += 1
        if not self.stop.is_set():
            self.disconnects += 1
            self.errors.append(f"{what} {k} disconnected ({ws.close_code})")

    async def _page(self, k: int) -> None:
        try:
            await self._page_session(k)
        except Exception as exc:  # noqa: BLE001 - recorded; the other pages go on
            self.errors.append(f"page {k}: {type(exc).__name__}: {exc}")

    async def _page_session(self, k: int) -> None:
        """Do what a studio page's script does (see the module notes)."""
        import aiohttp

        jar = aiohttp.CookieJar(unsafe=True)  # cookies of an IP-address host
        async with aiohttp.ClientSession(cookie_jar=jar) as session:
            async with session.get(self.studio_url) as response:  # ?token= -> cookie, redirect to /
                html = await response.text()
                if response.status != 200:
                    raise RuntimeError(f"page {k}: GET / answered {response.status}")
            for asset in re.findall(r'(?:src|href)="(/static/[^"]+)"', html):
                async with session.get(self.studio_base + asset) as response:
                    self.page_bytes_loaded += len(await response.read())
            ws = await session.ws_connect(f"{self.studio_base}/ws", headers={"Origin": self.studio_base})
            reader = asyncio.ensure_future(self._read(ws, self.page_messages, k, "page"))
            channel = k % CHANNELS + 1
            await ws.send_str(json.dumps({"type": "watch", "channel": channel}))
            rng = np.random.default_rng(31 + k)
            next_fetch = time.monotonic() + PAGE_FETCH_EVERY_S * (k + 1) / PAGES
            while not self.stop.is_set():
                await asyncio.sleep(PAGE_MOVE_EVERY_S)
                if not self.load.is_set() or ws.closed:
                    continue
                value = round(float(rng.uniform(0.1, 0.9)), 3)
                await ws.send_str(json.dumps({"type": "knob", "channel": channel, "name": "intensity", "value": value}))
                self.page_moves += 1
                if time.monotonic() >= next_fetch:
                    next_fetch += PAGE_FETCH_EVERY_S
                    for path in PAGE_FETCHES:
                        async with session.get(self.studio_base + path) as response:
                            await response.read()
                            self.page_fetches += 1
                            if response.status != 200:
                                self.errors.append(f"page {k}: GET {path} answered {response.status}")
            await ws.close()
            await reader


# ------------------------------------------------------------------ load threads
def every(
    period: float, load: threading.Event, stop: threading.Event, job: Callable[[], None], name: str, errors: list[str]
) -> threading.Thread:
    """Run ``job`` on a thread every ``period`` s while ``load`` is set (at once when it gets set), until ``stop``."""

    def run() -> None:
        due = 0.0
        while not stop.is_set():
            now = time.monotonic()
            if load.is_set() and now >= due:
                due = max(due + period, now)
                try:
                    job()
                except Exception as exc:  # noqa: BLE001 - a failed round is recorded, the soak goes on
                    errors.append(f"{name}: {type(exc).__name__}: {exc}")
            stop.wait(min(0.05, max(0.0, due - time.monotonic())) if load.is_set() else 0.05)

    thread = threading.Thread(target=run, name=f"soak-{name}", daemon=True)
    thread.start()
    return thread


PRESET = """version: 1
name: soak
description: 'bench_soak: rewritten every 10 s (reload {n})'
intensity: {intensity}
balance: {balance}
glide_ms: 50.0
"""


@dataclass
class Reloader:
    folder: Path
    studio_base: str
    token: str
    written: int = 0
    seen: int = 0
    pending: list[tuple[float, float]] = field(default_factory=list)

    def write(self) -> None:
        self.written += 1
        intensity = round(0.2 + 0.5 * ((self.written * 37) % 100) / 100.0, 3)
        text = PRESET.format(n=self.written, intensity=intensity, balance=round(-0.5 + (self.written % 10) / 10, 2))
        tmp = self.folder / ".soak.yaml.tmp"
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, self.folder / "soak.yaml")
        self.pending.append((time.monotonic() + RELOAD_CHECK_AFTER_S, intensity))

    def check(self) -> None:
        due = [p for p in self.pending if p[0] <= time.monotonic()]
        if not due:
            return
        self.pending = [p for p in self.pending if p[0] > time.monotonic()]
        request = urllib.request.Request(
            self.studio_base + "/api/presets", headers={"Authorization": f"Bearer {self.token}"}
        )
        with urllib.request.urlopen(request, timeout=10) as response:
            listing = json.loads(response.read())
        soak = [p for p in listing["presets"] if p.get("name") == "soak"]
        if soak and abs(float(soak[0]["intensity"]) - due[-1][1]) < 1e-6:
            self.seen += len(due)


# ------------------------------------------------------------------ sampling
def proc_numbers(pid: int) -> dict[str, float]:
    rss_kb = 0
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            rss_kb = int(line.split()[1])
    return {
        "rss_mb": rss_kb / 1024.0,
        "fds": len(os.listdir(f"/proc/{pid}/fd")),
        "threads": len(os.listdir(f"/proc/{pid}/task")),
        "cpu_s": proc_cpu_seconds(pid) or 0.0,
        **proc_memory(pid),
    }


MEMORY_KINDS = ("heap", "anon", "stack", "files")


def proc_memory(pid: int) -> dict[str, float]:
    """Resident MB by kind of mapping (``/proc/PID/smaps``), to say where RSS growth lives.

    ``heap``: the main malloc arena (``[heap]``); ``anon``: anonymous maps (other threads' malloc
    arenas, Python's object arenas, large buffers); ``stack``: thread stacks; ``files``: mapped
    libraries and files. Empty where smaps is unreadable.
    """
    kb = dict.fromkeys(MEMORY_KINDS, 0)
    kind = "anon"
    try:
        text = Path(f"/proc/{pid}/smaps").read_text()
    except OSError:
        return {}
    for line in text.splitlines():
        head = line.split(maxsplit=5)
        if head and "-" in head[0] and len(head) >= 5 and ":" not in head[0]:  # a mapping's first line
            name = head[5] if len(head) > 5 else ""
            kind = (
                "heap"
                if name == "[heap]"
                else "stack"
                if name.startswith("[stack")
                else "files"
                if name.startswith("/")
                else "anon"
            )
        elif line.startswith("Rss:"):
            kb[kind] += int(line.split()[1])
    return {f"rss_{k}_mb": round(v / 1024.0, 3) for k, v in kb.items()}


STATUS_KEYS = (
    "underflows",
    "errors",
    "malformed",
    "packets",
    "denied",
    "messages",
    "late_commands",
    "schedule_full",
    "oscquery_clients",
    "oscquery_listens",
    "oscquery_pushed",
    "oscquery_refused",
    "tcp_refused",
    "tcp_idle_closed",
    "send_errors",
    "subscribers",
    "clips_playing",
    "follow.losses",
    "follow.recoveries",
)


def growth(samples: list[dict], key: str, warmup_s: float = WARMUP_S) -> dict[str, float | None]:
    """Least-squares slope per hour of ``key`` over the samples after ``warmup_s`` (the first minute), its range.

    ``samples``: dicts with ``t`` (s since the start), ``window`` (samples of the ``end`` window, taken
    after every client left, are left out) and ``key``. Fewer than two samples: every figure None.
    """
    later = [s for s in samples if s["t"] >= warmup_s and s["window"] != "end"]
    if len(later) < 2:
        return dict.fromkeys(("per_hour", "range", "first", "last", "min", "max"), None) | {"n": len(later)}
    t = np.array([s["t"] for s in later])
    v = np.array([s[key] for s in later], float)
    slope = 0.0 if np.ptp(v) == 0 or np.ptp(t) == 0 else float(np.polyfit(t, v, 1)[0])
    return {
        "per_hour": slope * 3600.0,
        "range": float(v.max() - v.min()),
        "first": float(v[0]),
        "last": float(v[-1]),
        "min": float(v.min()),
        "max": float(v.max()),
        "n": len(later),
    }


def schedule(total_s: float, quiet_s: float, every_s: float) -> list[tuple[str, float, float]]:
    """Windows (kind, start, end): quiet first, then load with a quiet window every ``every_s``, quiet last."""
    windows: list[tuple[str, float, float]] = []
    t = 0.0
    windows.append(("quiet", t, t + quiet_s))
    t += quiet_s
    end_load = total_s - quiet_s
    next_quiet = every_s
    while t < end_load - 1e-9:
        stop = min(end_load, next_quiet)
        if stop - t > 1e-9:
            windows.append(("load", t, stop))
        t = stop
        if t < end_load - 1e-9:
            windows.append(("quiet", t, min(end_load, t + quiet_s)))
            t = min(end_load, t + quiet_s)
            next_quiet = t + every_s - quiet_s
    windows.append(("quiet", end_load, total_s))
    return windows


# ------------------------------------------------------------------ the run
def serve_config(args: argparse.Namespace, folder: Path, follow: Path) -> str:
    return (
        "  tcp: true\n"  # under the starter's "osc:\n  port: N" (its first lines)
        f"audio:\n  channels: {CHANNELS}\n  block_size: 128\n"
        f"presets:\n  user_dir: {json.dumps(str(folder / 'presets'))}\n  watch: true\n"
        "studio:\n  port: 0\n"
        "discovery:\n  advertise: false\n  oscquery_port: 0\n"
        f"follow:\n  enabled: true\n  device: {json.dumps(str(follow))}\n"
    )


def log_url(log: Path, name: str) -> str:
    found = re.search(rf"^{name}: (http://\S+)$", log.read_text(), re.M)
    if not found:
        raise RuntimeError(f"serve did not print its {name} URL:\n{log.read_text()}")
    return found.group(1)


def jackd_xrun_lines(jackd: JackServer | None) -> int:
    return 0 if jackd is None else jackd.log_text().count("XRun")


def run(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    total_s = args.minutes * 60.0
    windows = schedule(total_s, args.quiet_seconds, args.quiet_every)
    began = time.monotonic()

    def progress(what: str) -> None:
        print(f"soak: {time.monotonic() - began:.1f} s: {what}", file=sys.stderr, flush=True)

    follow, sounds = follow_file(folder, total_s + 120.0)
    progress("follow file written")
    (folder / "presets").mkdir()
    token = secrets.token_urlsafe(24)
    env = dict(
        os.environ,
        VIBSYNTH_STUDIO_TOKEN=token,
        XDG_CONFIG_HOME=str(folder / "xdg-config"),
        XDG_DATA_HOME=str(folder / "xdg-data"),
    )
    jackd: JackServer | None = None
    monitor: Monitor | None = None
    if args.output == "jack":
        jackd = JackServer("bench-soak", 48000, 128, folder, driver_args=("-P", str(CHANNELS)))
        jackd.start()
        monitor = Monitor(jackd.name)
        env.update(jackd.env, VIBSYNTH_HOST_API="JACK")
    errors: list[str] = []
    load, stop = threading.Event(), threading.Event()
    ctx = mp.get_context("spawn")
    flood_running, flood_stop = ctx.Event(), ctx.Event()
    flood_sent = ctx.Value("q", 0, lock=False)
    threads: list[threading.Thread] = []
    flood_proc = None
    proc = None
    try:
        proc, port = start_serve(
            folder, output="sounddevice" if jackd else "null", env=env, extra_config=serve_config(args, folder, follow)
        )
        progress(f"serve started (pid {proc.pid})")
        log = folder / "serve.log"
        studio_url, oscquery_url = log_url(log, "studio"), log_url(log, "oscquery")
        studio_base = studio_url.split("/?", 1)[0]
        oscquery_port = int(oscquery_url.rstrip("/").rsplit(":", 1)[1])
        studio_port = int(studio_base.rsplit(":", 1)[1])
        counted = Counted()
        osc = CountedClient(port, counted)
        status0 = osc.status()
        before_clients = proc_numbers(proc.pid)
        counted.sent = 0  # from here on every packet sent is counted (the first /status is in status0)
        flood_proc = ctx.Process(
            target=flood, args=(port, args.rate, flood_running, flood_stop, flood_sent), daemon=True
        )
        flood_proc.start()

        clients = Clients(oscquery_port, studio_base, studio_url, load, stop, errors)
        ready = threading.Event()
        client_thread = threading.Thread(target=clients.run, args=(ready,), name="soak-clients", daemon=True)
        client_thread.start()
        if not ready.wait(60):
            raise RuntimeError(f"the listeners and pages did not connect: {errors}")

        progress("listeners and pages connected")
        clip_state = {"n": 0, "played": 0}

        def retrigger() -> None:
            n = clip_state["n"]
            clip_state["n"] += 1
            osc.send(f"/vibsynth/ch/{n % CHANNELS + 1}/play", CLIPS[n % len(CLIPS)], 1.0, 1.0, 1, types="sffi")
            clip_state["played"] += 1

        reloader = Reloader(folder / "presets", studio_base, token)
        vanish_state = {"n": 0, **{k: 0 for k in VANISH_KINDS}}

        def vanish() -> None:
            kind = VANISH_KINDS[vanish_state["n"] % len(VANISH_KINDS)]
            vanish_state["n"] += 1
            if kind == "tcp-osc":
                vanish_tcp_osc(port, counted)
            elif kind == "oscquery-ws":
                vanish_oscquery(oscquery_port)
            else:
                vanish_studio(studio_port, token)
            vanish_state[kind] += 1

        always = threading.Event()
        always.set()
        threads += [
            every(CLIP_EVERY_S, load, stop, retrigger, "clips", errors),
            every(RELOAD_EVERY_S, load, stop, reloader.write, "reload", errors),
            every(0.5, always, stop, reloader.check, "reload-check", errors),  # a reload near a window's end too
            every(VANISH_EVERY_S, load, stop, vanish, "vanish", errors),
        ]

        samples: list[dict] = []
        window_rows: list[dict] = []
        start = time.monotonic()

        def sample(kind: str) -> dict:
            st = osc.status()
            row = {"t": round(time.monotonic() - start, 2), "window": kind, **proc_numbers(proc.pid)}
            row.update({k: st.get(k) for k in STATUS_KEYS})
            row["jack_xruns"] = monitor.xruns if monitor else None
            row["flood_sent"] = int(flood_sent.value)
            row["listener_pushes"] = sum(clients.listener_pushes)
            row["page_messages"] = sum(clients.page_messages)
            row["loadavg"] = round(os.getloadavg()[0], 2)
            samples.append(row)
            print(
                f"soak: t {row['t']:.0f} s {kind}: RSS {row['rss_mb']:.1f} MB, {row['fds']} files, "
                f"{row['threads']} threads, {row['underflows']} underflows, load average {row['loadavg']}",
                file=sys.stderr,
                flush=True,
            )
            return row

        next_sample = 0.0
        for kind, w_start, w_end in windows:
            while time.monotonic() - start < w_start:
                time.sleep(0.05)
            first = sample(kind)
            osc.send("/vibsynth/ch/*/follow", 1 if kind == "load" else 0, types="i")
            if kind == "load":
                load.set()
                flood_running.set()
            else:
                load.clear()
                flood_running.clear()
            xruns_lines0 = jackd_xrun_lines(jackd)
            next_sample = w_start + args.sample_seconds
            while (now := time.monotonic() - start) < w_end:
                if now >= next_sample:
                    sample(kind)
                    next_sample += args.sample_seconds
                time.sleep(min(0.2, max(0.01, min(w_end, next_sample) - now)))
            if kind == "load":  # the window's last sample sees the load stopped and serve's queue drained
                load.clear()
                flood_running.clear()
                time.sleep(0.3)
            last = sample(kind)
            window_rows.append(
                {
                    "window": kind,
                    "start_s": round(w_start, 1),
                    "seconds": round(last["t"] - first["t"], 2),
                    "underflows": int(last["underflows"] - first["underflows"]),
                    "jack_xruns": None if monitor is None else last["jack_xruns"] - first["jack_xruns"],
                    "jackd_xrun_lines": jackd_xrun_lines(jackd) - xruns_lines0,
                    "errors": int(last["errors"] - first["errors"]),
                    "malformed": int(last["malformed"] - first["malformed"]),
                    "flood_sent": last["flood_sent"] - first["flood_sent"],
                    "serve_cpu_pct": round(
                        100.0 * (last["cpu_s"] - first["cpu_s"]) / max(1e-9, last["t"] - first["t"]), 1
                    ),
                }
            )
            print(f"soak: {json.dumps(window_rows[-1])}", file=sys.stderr, flush=True)

        stop.set()
        for thread in threads:
            thread.join(timeout=10)
        client_thread.join(timeout=30)
        flood_stop.set()
        flood_proc.join(timeout=10)
        with osc.lock:
            osc.request("/vibsynth/sync", 1, expect="/vibsynth/synced", timeout=30.0)
        final = sample("end")
        progress("load stopped, clients gone")
        osc.close()
        log_text = log.read_text(errors="replace")
    finally:
        stop.set()
        flood_stop.set()
        if flood_proc is not None and flood_proc.is_alive():
            flood_proc.terminate()
        if proc is not None:
            stop_serve(proc)
        if monitor is not None:
            monitor.close()
        stop_all()

    sent = counted.sent + int(flood_sent.value)
    received = int(final["packets"] - status0["packets"])
    quiet = [w for w in window_rows if w["window"] == "quiet"]
    loaded = [w for w in window_rows if w["window"] == "load"]

    def per_min(rows: list[dict], key: str) -> float | None:
        seconds = sum(r["seconds"] for r in rows)
        return None if seconds <= 0 or any(r[key] is None for r in rows) else 60.0 * sum(r[key] for r in rows) / seconds

    log_problems = [
        line for line in log_text.splitlines() if "Traceback" in line or "error" in line.lower() and "vibsynth:" in line
    ]
    return {
        "benchmark": "soak",
        "settings": {
            "minutes": args.minutes,
            "output": "JACK dummy driver through PortAudio (48 kHz, block 128, 16 playback ports)"
            if jackd
            else "null output (system clock)",
            "jack_realtime": None if jackd is None else jackd.realtime,
            "channels": CHANNELS,
            "osc_rate": args.rate,
            "clips": CLIPS,
            "clip_every_s": CLIP_EVERY_S,
            "listeners": LISTENERS,
            "pages": PAGES,
            "pages_are": "aiohttp clients doing what the page's script does (no browser)",
            "preset_reload_every_s": RELOAD_EVERY_S,
            "vanish_every_s": VANISH_EVERY_S,
            "vanish_kinds": VANISH_KINDS,
            "follow": {"file": "FLAC of sound-theme-freedesktop's .oga sounds in turn", "sounds": len(sounds)},
            "quiet_seconds": args.quiet_seconds,
            "quiet_every": args.quiet_every,
            "sample_seconds": args.sample_seconds,
            "warmup_seconds": args.warmup_seconds,
        },
        "windows": window_rows,
        "underflows": {
            "quiet": sum(w["underflows"] for w in quiet),
            "load": sum(w["underflows"] for w in loaded),
            "quiet_seconds": round(sum(w["seconds"] for w in quiet), 1),
            "load_seconds": round(sum(w["seconds"] for w in loaded), 1),
            "quiet_per_min": per_min(quiet, "underflows"),
            "load_per_min": per_min(loaded, "underflows"),
            "jack_xruns_quiet_per_min": per_min(quiet, "jack_xruns"),
            "jack_xruns_load_per_min": per_min(loaded, "jack_xruns"),
        },
        "growth": {
            key: growth(samples, key, args.warmup_seconds)
            for key in ("rss_mb", "fds", "threads", *(f"rss_{k}_mb" for k in MEMORY_KINDS))
            if key in samples[0]
        },
        "before_and_after": {  # serve alone: before any client connected, and after every client left
            "before": before_clients,
            "after": {k: final[k] for k in ("rss_mb", "fds", "threads", "cpu_s")},
        },
        "messages": {
            "sent": sent,
            "flood": int(flood_sent.value),
            "received": received,
            "lost": sent - received,
        },
        "errors": {
            "serve_errors": int(final["errors"] - status0["errors"]),
            "serve_malformed": int(final["malformed"] - status0["malformed"]),
            "oscquery_refused": int(final["oscquery_refused"] - status0["oscquery_refused"]),
            "tcp_refused": int(final["tcp_refused"] - status0["tcp_refused"]),
            "send_errors": int(final["send_errors"] - status0["send_errors"]),
            "status_timeouts": osc.timeouts,  # /status not answered within 5 s (asked again)
            "benchmark": errors,
            "serve_log": log_problems[:50],
        },
        "load": {
            "clips_played": clip_state["played"],
            "reloads_written": reloader.written,
            "reloads_seen": reloader.seen,
            "vanished": {k: vanish_state[k] for k in VANISH_KINDS},
            "listener_pushes": sum(clients.listener_pushes),
            "listeners_silent": sum(1 for n in clients.listener_pushes if n == 0),
            "page_messages": sum(clients.page_messages),
            "page_moves": clients.page_moves,
            "page_fetches": clients.page_fetches,
            "disconnects": clients.disconnects,
            "follow_losses": final["follow.losses"],
            "serve_cpu_pct": 100.0 * (final["cpu_s"] - samples[0]["cpu_s"]) / max(1e-9, final["t"] - samples[0]["t"]),
        },
        "samples": samples,
        "machine": machine_info(),
        "load_average_end": os.getloadavg(),
        "when": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def print_table(result: dict) -> None:
    print(f"soak: {result['settings']['minutes']:g} min, {result['settings']['output']}")
    head = ("window", "start s", "seconds", "underflows", "JACK xruns", "errors", "flood msgs")
    print(" ".join(f"{h:>{w}}" for h, w in zip(head, (6, 8, 8, 10, 10, 6, 10))))
    for w in result["windows"]:
        xr = "-" if w["jack_xruns"] is None else str(w["jack_xruns"])
        print(
            f"{w['window']:>6} {w['start_s']:>8.0f} {w['seconds']:>8.1f} {w['underflows']:>10} {xr:>10} "
            f"{w['errors']:>6} {w['flood_sent']:>10}"
        )
    u = result["underflows"]
    fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
    print(
        f"\nunderflows/min: quiet {fmt(u['quiet_per_min'])} ({u['quiet']} in {u['quiet_seconds']:.0f} s), "
        f"load {fmt(u['load_per_min'])} ({u['load']} in {u['load_seconds']:.0f} s); JACK xruns/min quiet "
        f"{fmt(u['jack_xruns_quiet_per_min'])}, load {fmt(u['jack_xruns_load_per_min'])}"
    )
    print(f"\n{'after warmup':<12} {'first':>9} {'last':>9} {'min':>9} {'max':>9} {'growth/h':>10}")
    rows = [("rss_mb", "RSS MB"), *((f"rss_{k}_mb", f" of it {k}") for k in MEMORY_KINDS)]
    for key, label in (*rows, ("fds", "open files"), ("threads", "threads")):
        if key not in result["growth"]:
            continue
        g = result["growth"][key]
        if g["per_hour"] is None:
            print(f"{label:<12} (no samples after the first minute)")
            continue
        print(
            f"{label:<12} {g['first']:>9.1f} {g['last']:>9.1f} {g['min']:>9.1f} {g['max']:>9.1f} {g['per_hour']:>10.2f}"
        )
    m, e, ld = result["messages"], result["errors"], result["load"]
    print(f"\nOSC messages sent {m['sent']} (flood {m['flood']}), counted by serve {m['received']}, lost {m['lost']}")
    print(
        f"errors: serve {e['serve_errors']}, malformed {e['serve_malformed']}, benchmark {len(e['benchmark'])}, "
        f"serve log {len(e['serve_log'])}"
    )
    print(
        f"load: {ld['clips_played']} clips, {ld['reloads_seen']}/{ld['reloads_written']} reloads seen, "
        f"vanished {ld['vanished']}, {ld['listener_pushes']} pushes to listeners, {ld['page_messages']} page "
        f"messages, {ld['page_moves']} page moves, {ld['page_fetches']} page fetches, "
        f"serve CPU {ld['serve_cpu_pct']:.1f} % of a core"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=30.0, help="length of the run, quiet windows included")
    parser.add_argument("--output", choices=("jack", "null"), default="jack")
    parser.add_argument("--rate", type=int, default=10_000, help="OSC flood, messages per second")
    parser.add_argument("--quiet-seconds", type=float, default=30.0, help="length of each quiet window")
    parser.add_argument("--quiet-every", type=float, default=300.0, help="a quiet window every this many seconds")
    parser.add_argument("--sample-seconds", type=float, default=10.0)
    parser.add_argument("--warmup-seconds", type=float, default=WARMUP_S, help="growth is fitted after this")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "soak.json")
    args = parser.parse_args(argv)
    if args.minutes * 60.0 < 3 * args.quiet_seconds:
        parser.error("--minutes must leave room for the first and last quiet windows and some load")
    with tempfile.TemporaryDirectory(prefix="bench-soak-") as tmp:
        result = run(args, Path(tmp))
    print_table(result)
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
