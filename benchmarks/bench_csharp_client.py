#!/usr/bin/env python3
"""C# client benchmark: query round trip and set -> get latency of clients/csharp/VibsynthClient.cs.

    scripts/with_jack.sh -- .venv/bin/python benchmarks/bench_csharp_client.py [--trials 2000]
    .venv/bin/python benchmarks/bench_csharp_client.py            # null output when no JACK server runs

Compiles the client and benchmarks/csharp/ClientBench.cs with mono's mcs, starts a real
``vibsynth serve`` (on the JACK dummy driver when a JACK server is reachable, else the null output)
and runs the program with mono on the same machine. Per trial, timed with the C# Stopwatch:

* **get**: ``GetIntensity(1)`` (blocking): ``/ch/1/get`` sent, reply matched by the receive thread;
* **get (await)**: ``await GetIntensityAsync(1)`` on the thread pool;
* **ping**: ``Ping()``, ``/ping`` -> ``/pong``;
* **set call**: the ``SetIntensity`` call alone (validation, encoding, ``sendto``): what a frame pays;
* **set -> get**: ``SetIntensity(v)`` then ``GetIntensity()`` returning v (values alternate; a
  mismatch is counted): the time until the server's state reflects a set, seen by the app;
* **1000 in flight**: 1000 ``GetIntensityAsync`` started at once, time until all answered.

For reference the Python client's ``get`` round trip is measured against the same server.
Median and p99 over the trials (after a warm-up that JIT-compiles the paths). Prints a table and
writes JSON to benchmarks/results/csharp_client.json.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_osc import write_json  # noqa: E402

import vibsynth  # noqa: E402
from tests.clients.mono import CLIENT, compile_cs, run_mono  # noqa: E402
from tests.e2e.test_osc_e2e import jack_available, start_serve, stop_serve  # noqa: E402

BENCH = ROOT / "benchmarks" / "csharp" / "ClientBench.cs"
ROWS = (
    ("get", "get (blocking)"),
    ("get_await", "get (await)"),
    ("ping", "ping"),
    ("set_call", "set call"),
    ("set_get", "set -> get"),
    ("python_get", "Python client get"),
)


def _stats(samples_us: list[float]) -> dict[str, float]:
    values = np.asarray(samples_us, dtype=float)
    return {
        "trials": int(values.size),
        "median_us": float(np.median(values)),
        "p99_us": float(np.percentile(values, 99)),
        "max_us": float(values.max()),
    }


def _python_get(port: int, trials: int) -> list[float]:
    times = []
    with vibsynth.Client(port=port, timeout=5.0) as client:
        for i in range(trials + trials // 10):
            start = time.perf_counter()
            client.get("intensity", 1)
            if i >= trials // 10:
                times.append((time.perf_counter() - start) * 1e6)
    return times


def _mono_version() -> str:
    done = subprocess.run(["mono", "--version"], capture_output=True, text=True, check=False)
    return done.stdout.splitlines()[0] if done.stdout else "?"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=2000)
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "csharp_client.json")
    args = parser.parse_args()
    if shutil.which("mcs") is None or shutil.which("mono") is None:
        print("mcs and mono are needed (Debian mono-mcs, mono-runtime; scripts/setup.sh --test)", file=sys.stderr)
        return 2

    jack = jack_available()
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1") if jack else None
    with tempfile.TemporaryDirectory() as tmp:
        exe = compile_cs(Path(tmp) / "ClientBench.exe", CLIENT, BENCH)
        proc, port = start_serve(Path(tmp), output="sounddevice" if jack else "null", env=env)
        try:
            time.sleep(1.0)
            seen = run_mono(exe, port, args.trials, timeout=600)
            python_get = _python_get(port, args.trials)
        finally:
            stop_serve(proc)

    samples = {name: [float(v) for v in seen[name].split(",")] for name, _ in ROWS if name in seen}
    samples["python_get"] = python_get
    pipelined = [float(v) for v in seen["pipelined_1000"].split(",")]
    result = {
        "output": "jack (dummy driver)" if jack else "null",
        "measures": {name: _stats(samples[name]) for name, _ in ROWS},
        "pipelined_1000": {
            "rounds": len(pipelined),
            "median_ms": float(np.median(pipelined)) / 1e3,
            "queries_per_s": 1000.0 / (float(np.median(pipelined)) / 1e6),
        },
        "set_get_mismatched": int(seen["set_get.mismatched"]),
        "malformed": int(seen["malformed"]),
        "machine": {
            "python": platform.python_version(),
            "mono": _mono_version(),
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
        },
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    print(f"C# client against vibsynth serve ({result['output']} output), localhost UDP, {args.trials} trials")
    print(f"{'measure':<20} {'median µs':>10} {'p99 µs':>10} {'max µs':>10}")
    for name, label in ROWS:
        row = result["measures"][name]
        print(f"{label:<20} {row['median_us']:>10.0f} {row['p99_us']:>10.0f} {row['max_us']:>10.0f}")
    pipe = result["pipelined_1000"]
    print(f"1000 queries in flight: {pipe['median_ms']:.1f} ms ({pipe['queries_per_s']:.0f} queries/s)")
    print(f"set -> get returned another value: {result['set_get_mismatched']} times")
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
