#!/usr/bin/env python3
"""Studio latency: a page's input event -> the engine's knob, and an OSC message -> the page's DOM.

    python benchmarks/bench_studio_latency.py [--trials 300] [--output null|sounddevice]
    scripts/with_jack.sh -- python benchmarks/bench_studio_latency.py --output sounddevice

The service runs in this process (engine, output, Controller, OSC server and studio wired as
``vibsynth serve`` wires them), so the engine itself can be watched; the page runs in a real
headless Chromium (Selenium).

* **input -> engine**: the page's intensity slider gets a new value and an ``input`` event
  (timestamped in the page just before the event is dispatched: the page's own handler sends
  the WebSocket message); a thread of this process watches ``engine.knob_values()`` (glide 0)
  and timestamps the moment the audio thread applied the value. It includes the WebSocket,
  the studio's loop, the Controller, the hand-off to the engine and the wait for the next
  audio block (block 128 at 48 kHz: up to 2.7 ms). Watch resolution: 0.2 ms.
* **OSC -> page**: this process sends ``/vibsynth/ch/1/intensity`` over UDP (timestamped
  before the send); the page records when its handler has written the value into the DOM
  (``window.__studioRecord``). It includes the OSC receive loop, the Controller's event, the
  studio's coalescing push and the browser's handling.

Both sides use the wall clock: the page's ``performance.timeOrigin + performance.now()`` and
Python's ``time.time()``; their offset is measured (the reading with the shortest round trip
of 50) and removed. Trials are 40 ms apart (no coalescing between them).

Prints a table and writes JSON to benchmarks/results/studio_latency.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from latency_stats import summary_ms  # noqa: E402 - benchmarks/, beside this script

from tests.e2e.oscclient import OscClient  # noqa: E402
from tests.e2e.studioutil import chromium, wait_for  # noqa: E402

GAP_S = 0.04


def start_service(output: str) -> SimpleNamespace:
    """Engine, output, Controller, OSC server and studio, wired like ``vibsynth serve`` (one channel)."""
    from vibsynth.app.service import build_engine, open_output
    from vibsynth.control.controller import Controller
    from vibsynth.control.osc import adapter as osc_adapter
    from vibsynth.control.studio import adapter as studio_adapter
    from vibsynth.settings.config import load_config

    overrides = {"audio.backend": output, "audio.channels": 1, "osc.port": 0}
    settings = load_config(overrides=overrides, env={}, user_file=False).settings
    engine = build_engine(settings)
    controller = Controller.for_knobs(engine, settings.knobs)
    controller.set_glide(0.0, source="benchmark")  # a move is applied in one block: its arrival is visible
    out = open_output(settings.audio, engine, output == "sounddevice")
    controller.output = out  # type: ignore[attr-defined]
    osc = osc_adapter.create(settings, None, controller)
    osc.start()
    args = SimpleNamespace(no_studio=False, studio_port=0, studio_token=None)
    studio = studio_adapter.create(settings, args, controller, None, servers=[osc])
    studio.start()
    out.start()
    return SimpleNamespace(engine=engine, controller=controller, output=out, osc=osc, studio=studio)


def clock_offset_ms(driver: Any) -> float:
    """Page clock minus this process's clock (ms), from the reading with the shortest round trip."""
    best = (float("inf"), 0.0)
    for _ in range(50):
        before = time.time() * 1000.0
        page = driver.execute_script("return performance.timeOrigin + performance.now();")
        after = time.time() * 1000.0
        best = min(best, (after - before, page - (before + after) / 2.0))
    return best[1]


def input_to_engine(driver: Any, service: SimpleNamespace, trials: int, offset_ms: float) -> list[float]:
    """Slider input event (page clock) -> value applied by the audio thread (this clock), in ms.

    Each trial starts from intensity 0 (set directly and seen applied), so the value the
    watcher waits for cannot be there already.
    """
    engine = service.engine
    latencies = []
    for k in range(trials):
        value = round(0.2 + (k % 700) * 0.001, 3)
        service.controller.set_knob("intensity", 0.0, source="benchmark")
        wait_for(lambda: engine.knob_values()[0][0] == 0.0, timeout=2, what="intensity 0 applied")
        seen = threading.Event()
        stamp: list[float] = []

        def watch() -> None:
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                if abs(engine.knob_values()[0][0] - value) < 1e-6:
                    stamp.append(time.time() * 1000.0)
                    seen.set()
                    return
                time.sleep(0.0002)
            seen.set()

        watcher = threading.Thread(target=watch)
        watcher.start()
        sent = driver.execute_script(
            "const s = document.querySelector('[data-testid=\"intensity\"]');"
            "s.value = arguments[0];"
            "const t = performance.timeOrigin + performance.now();"
            "s.dispatchEvent(new Event('input', {bubbles: true}));"
            "return t;",
            f"{value:.3f}",
        )
        seen.wait(3.0)
        watcher.join()
        if stamp:
            latencies.append(stamp[0] - (sent - offset_ms))
        time.sleep(GAP_S)
    return latencies


def osc_to_page(driver: Any, osc_port: int, trials: int, offset_ms: float) -> list[float]:
    """OSC send (this clock) -> the page's DOM showing the value (page clock), in ms."""
    client = OscClient(osc_port)
    driver.execute_script("window.__studioRecord = [];")
    latencies = []
    try:
        for k in range(trials):
            value = float(np.float32(0.3 + (k % 400) * 0.001 + (0.4 if k % 2 else 0.0)))
            sent = time.time() * 1000.0
            client.send("/vibsynth/ch/1/intensity", value)
            shown = wait_for(
                lambda: driver.execute_script(
                    "const r = window.__studioRecord.find((e) => Math.abs(e.value - arguments[0]) < 1e-7);"
                    "return r ? r.t : null;",
                    value,
                ),
                timeout=5,
                what=f"intensity {value} on the page",
            )
            latencies.append((shown - offset_ms) - sent)
            driver.execute_script("window.__studioRecord = [];")
            time.sleep(GAP_S)
    finally:
        client.close()
    return latencies


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--output", choices=("null", "sounddevice"), default="null")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "studio_latency.json")
    args = parser.parse_args()

    service = start_service(args.output)
    driver = chromium()
    try:
        driver.get(service.studio.url)
        wait_for(
            lambda: driver.execute_script("return document.getElementById('connection').dataset.state") == "open",
            what="the page to connect",
        )
        wait_for(lambda: driver.execute_script("return window.studio && window.studio.hello !== null"), what="hello")
        offset = clock_offset_ms(driver)
        input_to_engine(driver, service, 20, offset)  # warm-up: the first messages pay for imports and JIT
        engine_ms = input_to_engine(driver, service, args.trials, offset)
        page_ms = osc_to_page(driver, service.osc.port, args.trials, offset)
    finally:
        driver.quit()
        service.studio.stop()
        service.osc.stop()
        service.output.stop()

    results = {
        "benchmark": "studio latency",
        "output": service.output.describe(),
        "block_size": getattr(service.output, "block_size", None),
        "fs": service.engine.fs,
        "trials": args.trials,
        "clock_offset_ms": round(offset, 3),
        "input_to_engine": summary_ms(engine_ms),
        "osc_to_page": summary_ms(page_ms),
        "machine": (
            f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
        ),
        "browser": "headless Chromium (Selenium)",
        "date": time.strftime("%Y-%m-%d"),
    }
    print(f"studio latency ({args.trials} trials each; {results['output']})")
    print(f"{'path':<32} {'median ms':>10} {'p99 ms':>10} {'min ms':>10} {'max ms':>10}")
    for label, key in (("input event -> engine", "input_to_engine"), ("OSC -> page DOM", "osc_to_page")):
        s = results[key]
        print(f"{label:<32} {s['median_ms']:>10.2f} {s['p99_ms']:>10.2f} {s['min_ms']:>10.2f} {s['max_ms']:>10.2f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
