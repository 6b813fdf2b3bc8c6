#!/usr/bin/env python3
"""VRChat bridge: avatar parameter -> audible change latency, and what a parameter costs the OSC handler.

Latency (needs a JACK server: ``scripts/with_jack.sh -- .venv/bin/python benchmarks/bench_vrchat.py``):
``vibsynth serve`` with the shipped vest example (vibsynth/data/config/vrchat-vest.yaml, 16 channels)
on the JACK dummy driver; a proximity ``ChestL`` (level drive, a source at the left chest) goes
from 0 to 0.8 as one UDP datagram from this machine, the vest's channel 1 is captured from JACK.
``onset``: from the datagram to the first non-zero sample; ``done``: to the first 5 ms window whose
level is within 1 dB of the level that follows. A stroke (``ChestR``, velocity drive) is measured the
same way from its second value, 11 ms after the first (after ``/avatar/change``, the first has no rate);
its ``done`` is the first window within 1 dB of its loudest in the first 100 ms (it fades after).

Cost (in process, no socket): ``OscHandler.handle_packet`` per datagram for an unmapped avatar
parameter (dropped before decoding), a mapped one (a source moved), and ``/vibsynth/intensity``.

Prints tables and writes JSON to benchmarks/results/vrchat.json.
"""

from __future__ import annotations

import argparse
import json
import math
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

from tests.control.osc.fakes import FakePeer, make_controller  # noqa: E402
from tests.e2e.jackutil import JackCapture, portaudio_output_ports  # noqa: E402
from tests.e2e.oscclient import OscClient  # noqa: E402
from tests.e2e.test_osc_e2e import jack_available, start_serve, stop_serve  # noqa: E402
from vibsynth.control.osc.codec import encode_message  # noqa: E402
from vibsynth.control.osc.handler import OscHandler  # noqa: E402
from vibsynth.control.osc.tables import register_tables  # noqa: E402
from vibsynth.control.vrchat.bridge import ROOT as AVATAR_ROOT  # noqa: E402
from vibsynth.control.vrchat.bridge import VrchatBridge  # noqa: E402
from vibsynth.formats.files import atomic_write_text  # noqa: E402
from vibsynth.settings.models_vrchat import Vrchat  # noqa: E402

EXAMPLE = ROOT / "vibsynth" / "data" / "config" / "vrchat-vest.yaml"


def _summary(values_ms: list[float]) -> dict:
    ordered = sorted(values_ms)
    return {
        "median_ms": statistics.median(ordered),
        "p95_ms": ordered[min(len(ordered) - 1, int(math.ceil(0.95 * len(ordered))) - 1)],
        "max_ms": ordered[-1],
    }


def _windows_db(x: np.ndarray, hop: int) -> np.ndarray:
    n = len(x) // hop
    power = np.mean(x[: n * hop].reshape(n, hop) ** 2, axis=1)
    with np.errstate(divide="ignore"):
        return 10 * np.log10(power)


def latency(trials: int) -> dict:
    """Parameter -> first non-zero sample and -> settled, for a level and a velocity drive."""
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    example = EXAMPLE.read_text(encoding="utf-8").replace("version: 1\n", "")
    example = example.replace("  enabled: true\n", "  enabled: true\n  listen_port: 0\n", 1)
    with tempfile.TemporaryDirectory() as tmp:
        proc, port = start_serve(
            Path(tmp), output="sounddevice", env=env, extra_config=example + "studio: {enabled: false}\n"
        )
        client = OscClient(port)
        out: dict = {}
        try:
            with JackCapture(0.6, n_ports=2) as cap:
                cap.connect(
                    sorted(portaudio_output_ports(cap.client), key=lambda name: int(name.rsplit("_", 1)[1]))[:2]
                )
                rate = cap.rate
                for name, channel in (("ChestL", 0), ("ChestR", 1)):
                    onsets, dones = [], []
                    for _ in range(trials):
                        if name == "ChestL":
                            client.send(f"/avatar/parameters/{name}", 0.0)
                        else:
                            client.send("/avatar/change", "avtr_bench")  # the stroke's first value has no rate
                        time.sleep(0.6)  # a velocity drive fades in 0.3 s
                        cap.reset()
                        cap.arm()
                        while cap.start_frame is None:
                            time.sleep(0.001)
                        time.sleep(0.05)
                        if name == "ChestR":
                            client.send(f"/avatar/parameters/{name}", 0.02)
                            time.sleep(1 / 90)
                        sent = cap.frame_time_now()
                        client.send(f"/avatar/parameters/{name}", 0.8 if name == "ChestL" else 0.04)
                        assert cap.wait(), "capture did not complete"
                        x = cap.data[:, channel].astype(np.float64)
                        at = sent - int(cap.start_frame)
                        loud = np.flatnonzero(np.abs(x[at:]) > 0)
                        if cap.gaps or not len(loud):
                            continue
                        onsets.append(1000.0 * loud[0] / rate)
                        hop = rate // 200
                        levels = _windows_db(x[at:], hop)
                        settled = levels[len(levels) // 2 :] if name == "ChestL" else levels[: len(levels) // 5]
                        target = np.median(settled) if name == "ChestL" else np.max(settled)
                        done = np.flatnonzero(levels >= target - 1.0)
                        dones.append(1000.0 * (done[0] + 1) * hop / rate)
                    out[name] = {"trials": len(onsets), "onset": _summary(onsets), "done": _summary(dones)}
        finally:
            client.close()
            stop_serve(proc)
    return out


def cost(n: int = 100_000) -> dict:
    """Microseconds per datagram through the handler: unmapped, mapped, and a knob for reference."""
    ctl = make_controller(channels=16)
    handler = register_tables(OscHandler(ctl, sync_worker=None))
    settings = Vrchat(enabled=True, parameters=[{"name": "Hug", "channel": 7}])
    handler.register_namespace(AVATAR_ROOT, VrchatBridge(settings, ctl))
    peer = FakePeer()
    cases = {
        "unmapped avatar parameter": [encode_message(f"/avatar/parameters/Unknown{k}", (0.5,)) for k in range(1000)],
        "mapped avatar parameter (a channel)": [
            encode_message("/avatar/parameters/Hug", (k / 1000,)) for k in range(1000)
        ],
        "/vibsynth/intensity (reference)": [encode_message("/vibsynth/intensity", (k / 1000,)) for k in range(1000)],
    }
    out = {}
    for label, packets in cases.items():
        t0 = time.perf_counter()
        for k in range(n):
            handler.handle_packet(packets[k % 1000], peer)
        out[label] = 1e6 * (time.perf_counter() - t0) / n
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "vrchat.json")
    args = parser.parse_args()
    result: dict = {"latency": None}
    if jack_available():
        result["latency"] = latency(args.trials)
    else:
        print("no JACK server (run under scripts/with_jack.sh): latency not measured", file=sys.stderr)
    result["cost_us"] = cost()
    result["machine"] = {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()}
    result["when"] = time.strftime("%Y-%m-%d %H:%M:%S")
    if result["latency"]:
        print("avatar parameter -> audible change (JACK dummy, ms)")
        print(f"{'parameter':>10} {'trials':>6} {'onset med':>9} {'onset p95':>9} {'done med':>9} {'done p95':>9}")
        for name, r in result["latency"].items():
            o, d = r["onset"], r["done"]
            print(
                f"{name:>10} {r['trials']:>6} {o['median_ms']:>9.2f} {o['p95_ms']:>9.2f} "
                f"{d['median_ms']:>9.2f} {d['p95_ms']:>9.2f}"
            )
    print("\nOSC handler cost per datagram (us)")
    for label, us in result["cost_us"].items():
        print(f"{label:>40} {us:8.2f}")
    atomic_write_text(args.json, json.dumps(result, indent=2))
    print(f"\nJSON written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
