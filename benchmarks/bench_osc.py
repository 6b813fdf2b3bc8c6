#!/usr/bin/env python3
"""OSC benchmark: message -> first output sample reflecting it (latency), and the maximum
sustained message rate without loss, against a real ``vibsynth serve`` process.

    scripts/with_jack.sh -- python benchmarks/bench_osc.py [--trials 50] [--rates 10000,20000,40000,80000]

Latency (needs JACK): the server streams through PortAudio into JACK; a JACK client
records its output continuously. Each trial jumps intensity 0 -> 0.8 (glide 0) over OSC,
noting the JACK frame clock at the send; the latency is the time from the send to the
first non-zero captured sample. Without JACK the latency column reports the OSC round trip
of ``/sync`` -> ``/synced`` (command applied by the engine) on the null output instead.

Rate: for each rate, valid knob messages are sent for ``--seconds`` in 1 ms bursts; the
server's packet counter (``/status``) gives received vs sent; underflows are read the same way.

Prints a table and writes JSON to benchmarks/results/osc.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.e2e.test_osc_e2e import Client, jack_available, start_serve, stop_serve  # noqa: E402
from vibsynth.control.osc.codec import encode_message  # noqa: E402


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def latency_jack(port: int, trials: int) -> list[float]:
    """Send-to-first-sample latencies (s) measured on the JACK frame clock."""
    from tests.e2e.jackutil import JackCapture, portaudio_output_ports

    client = Client(port)
    client.send("/vibsynth/glide", 0.0)
    client.send("/vibsynth/intensity", 0.0)
    gap_s = 0.12
    sends: list[int] = []
    with JackCapture(trials * 2 * gap_s * 1.5 + 2.0) as cap:
        cap.connect(portaudio_output_ports(cap.client)[:1])
        cap.arm()
        time.sleep(0.2)
        for _ in range(trials):
            client.send("/vibsynth/intensity", 0.0)
            time.sleep(gap_s)
            sends.append(cap.frame_time_now())
            client.send("/vibsynth/intensity", 0.8)
            time.sleep(gap_s)
        time.sleep(gap_s)
        data, start, rate = cap.data[:, 0].copy(), cap.start_frame, cap.rate
        cap_frames = cap.frames_captured
    client.close()
    latencies = []
    rejected = {"outside capture": 0, "not silent before": 0, "no onset": 0}
    for sent in sends:
        first = sent - start
        if first < 64 or first + int(gap_s * rate) > cap_frames:
            rejected["outside capture"] += 1
            continue
        if np.any(np.abs(data[first - 64 : first]) > 1e-7):
            rejected["not silent before"] += 1
            continue
        nonzero = np.flatnonzero(np.abs(data[first : first + int(gap_s * rate)]) > 1e-7)
        if not nonzero.size:
            rejected["no onset"] += 1
            continue
        latencies.append(nonzero[0] / rate)
    if any(rejected.values()):
        print(f"latency trials rejected: {rejected} (start frame {start}, captured {cap_frames})", file=sys.stderr)
    return latencies


def latency_sync(port: int, trials: int) -> list[float]:
    """Round trip of a knob message followed by /sync (engine applied it) on any output."""
    client = Client(port)
    out = []
    for k in range(trials):
        t0 = time.perf_counter()
        client.send("/vibsynth/intensity", 0.5 if k % 2 else 0.0)
        client.request("/vibsynth/sync", k, expect="/vibsynth/synced")
        out.append(time.perf_counter() - t0)
    client.close()
    return out


def rate_test(port: int, rate: int, seconds: float) -> dict:
    client = Client(port)
    messages = [
        encode_message(f"/vibsynth/ch/1/{'intensity' if k % 2 else 'balance'}", ((k % 100) / 100.0,), "f")
        for k in range(200)
    ]
    before = client.status()
    per_ms = max(1, rate // 1000)
    sent = 0
    start = time.perf_counter()
    next_t = start
    while next_t < start + seconds:
        for _ in range(per_ms):
            client.sock.sendto(messages[sent % 200], client.target)
            sent += 1
        next_t += per_ms / rate
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    elapsed = time.perf_counter() - start
    client.request("/vibsynth/sync", 1, expect="/vibsynth/synced", timeout=30.0)
    after = client.status()
    client.close()
    received = int(after["packets"] - before["packets"] - 2)
    return {
        "rate_target": rate,
        "sent": sent,
        "rate_sent": sent / elapsed,
        "received": received,
        "lost": sent - received,
        "underflows": int(after["underflows"] - before["underflows"]),
        "render_load": float(after["load"]),
    }


def write_json(path: Path, result: dict) -> None:
    """Write a benchmark's result as JSON (its folder created) and say where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2), encoding="utf-8")
    print(f"\nJSON: {path}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--rates", default="10000,20000,40000,80000")
    parser.add_argument("--seconds", type=float, default=5.0, help="duration of each rate step")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "osc.json")
    args = parser.parse_args()

    jack = jack_available()
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1") if jack else None
    with tempfile.TemporaryDirectory() as tmp:
        proc, port = start_serve(Path(tmp), output="sounddevice" if jack else "null", env=env)
        try:
            time.sleep(1.0)
            mode = "jack-capture" if jack else "sync-roundtrip-null"
            lat = latency_jack(port, args.trials) if jack else latency_sync(port, args.trials)
            rates = [rate_test(port, int(r), args.seconds) for r in args.rates.split(",")]
        finally:
            stop_serve(proc)

    lossless = [r["rate_sent"] for r in rates if r["lost"] == 0]
    result = {
        "latency": {
            "mode": mode,
            "trials": len(lat),
            "median_ms": 1e3 * statistics.median(lat) if lat else None,
            "p99_ms": 1e3 * _percentile(lat, 99),
            "max_ms": 1e3 * max(lat) if lat else None,
        },
        "rates": rates,
        "max_lossless_rate": max(lossless) if lossless else 0.0,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    latency = result["latency"]
    print(
        f"latency ({mode}, {latency['trials']} trials): median {latency['median_ms']:.2f} ms, "
        f"p99 {latency['p99_ms']:.2f} ms, max {latency['max_ms']:.2f} ms"
    )
    print(f"{'target/s':>9} {'sent/s':>9} {'sent':>8} {'received':>9} {'lost':>6} {'underflows':>10} {'load':>6}")
    for r in rates:
        print(
            f"{r['rate_target']:>9} {r['rate_sent']:>9.0f} {r['sent']:>8} {r['received']:>9} {r['lost']:>6} "
            f"{r['underflows']:>10} {r['render_load']:>6.2f}"
        )
    print(f"max sustained rate without loss: {result['max_lossless_rate']:.0f} msg/s")
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
