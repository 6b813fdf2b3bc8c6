#!/usr/bin/env python3
"""Clips under an OSC flood (issue 16): 16 channels each looping a clip vs the same flood without clips.

    python benchmarks/bench_clip_flood.py [--trials 3] [--seconds 10] [--quiet 5]

It starts its own JACK server on the dummy driver with 16 playback ports (``jackd -n
bench-clips -R -d dummy -r 48000 -p 128 -P 16``, without ``-R`` when real-time scheduling is
refused; benchmarks/bench_peers.py's ``JackServer``), and each trial starts a fresh
``vibsynth serve`` on it (16 channels through PortAudio) and, per condition:

* **textures**: every channel plays a texture (``/vibsynth/texture 0.5 0``), no clip;
* **clips**: every channel loops a shipped clip until stopped (``/vibsynth/ch/{n}/play NAME 1 1 0``,
  the five shipped clips in turn): 16 playbacks whose moves the clip player keeps submitted
  150 ms ahead.

Then ``--quiet`` seconds without traffic (the baseline), then ``--seconds`` of the OSC flood of
benchmarks/bench_osc.py (``rate_test``: 10,000 messages/s, ``/vibsynth/ch/1/intensity`` and
``balance`` alternating, in 1 ms bursts; under a clip those knob messages are remembered, and
the compiled fast path hands them to Python). Measured per window, from the server's
``/status`` (its PortAudio callback counts underflows and times every render) and a JACK client
on the same server:

* underflows (PortAudio) and JACK xruns (any client), quiet and flood;
* the render load (render time / block period, the engine's average) and JACK's DSP load
  (mean and max of samples every 0.25 s during the flood): the callback's timing;
* late commands (scheduled moves that reached the engine after their frame: the clip player
  falling behind) and clip moves refused (``clip.schedule_full``);
* messages lost and the serve process' CPU (% of one core).

The conditions alternate within each trial (textures first in odd trials). Prints a table and
writes JSON to benchmarks/results/clip_flood.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_osc import rate_test, write_json  # noqa: E402
from bench_peers import JackServer, Monitor, machine_info, proc_cpu_seconds, stop_all  # noqa: E402

from tests.e2e.test_osc_e2e import Client, start_serve, stop_serve  # noqa: E402

CHANNELS = 16
CLIPS = ("rain", "heartbeat", "gravel-steps", "zipper", "impact")
CONDITIONS = ("textures", "clips")


class DspSampler:
    """JACK's DSP load every ``period`` seconds, on a thread, while running."""

    def __init__(self, monitor: Monitor, period: float = 0.25) -> None:
        self.monitor, self.period = monitor, period
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.samples.append(self.monitor.cpu_load())

    def __enter__(self) -> DspSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def start(condition: str, port: int) -> None:
    client = Client(port)
    try:
        if condition == "clips":
            for n in range(1, CHANNELS + 1):
                client.send(f"/vibsynth/ch/{n}/play", CLIPS[(n - 1) % len(CLIPS)], 1.0, 1.0, 0, types="sffi")
        else:
            client.send("/vibsynth/texture", 0.5, 0.0)
        client.request("/vibsynth/sync", 1, expect="/vibsynth/synced")
        time.sleep(1.0)
        status = client.status()
        playing = status.get("clips_playing", 0)
        want = CHANNELS if condition == "clips" else 0
        if playing != want:
            raise RuntimeError(f"{condition}: {playing} clips playing, expected {want}")
    finally:
        client.close()


def run_condition(condition: str, args: argparse.Namespace, jackd: JackServer, monitor: Monitor, tmp: Path) -> dict:
    env = dict(jackd.env, VIBSYNTH_HOST_API="JACK")
    extra = f"audio:\n  channels: {CHANNELS}\n  block_size: 128\n"
    proc, port = start_serve(tmp, output="sounddevice", env=env, extra_config=extra)
    try:
        time.sleep(1.0)
        start(condition, port)
        client = Client(port)
        s0, x0 = client.status(), monitor.xruns
        time.sleep(args.quiet)
        s1, x1 = client.status(), monitor.xruns
        cpu0, t0 = proc_cpu_seconds(proc.pid), time.monotonic()
        with DspSampler(monitor) as dsp:
            flood = rate_test(port, args.rate, args.seconds)
        cpu1, t1 = proc_cpu_seconds(proc.pid), time.monotonic()
        s2, x2 = client.status(), monitor.xruns
        client.close()
    finally:
        stop_serve(proc)
    return {
        "condition": condition,
        "quiet_s": args.quiet,
        "flood_s": args.seconds,
        "underflows_quiet": int(s1["underflows"] - s0["underflows"]),
        "underflows_flood": int(s2["underflows"] - s1["underflows"]),
        "xruns_quiet": x1 - x0,
        "xruns_flood": x2 - x1,
        "render_load_flood": float(s2["load"]),
        "render_load_peak": float(s2["load_peak"]),
        "dsp_mean": statistics.fmean(dsp.samples) if dsp.samples else None,
        "dsp_max": max(dsp.samples) if dsp.samples else None,
        "late_commands_flood": int(s2["late_commands"] - s1["late_commands"]),
        "clips_playing": int(s2.get("clips_playing", 0)),
        "sent": flood["sent"],
        "rate_sent": flood["rate_sent"],
        "lost": flood["lost"],
        "errors": int(s2["errors"] - s1["errors"]),
        "cpu_pct": None if cpu0 is None or cpu1 is None else 100.0 * (cpu1 - cpu0) / (t1 - t0),
    }


def summary(rows: list[dict]) -> dict:
    out: dict = {}
    for condition in CONDITIONS:
        mine = [r for r in rows if r["condition"] == condition]
        if not mine:
            continue
        out[condition] = {
            key: {"median": statistics.median(vals), "max": max(vals), "values": vals}
            for key in (
                "underflows_quiet",
                "underflows_flood",
                "xruns_flood",
                "render_load_flood",
                "dsp_mean",
                "dsp_max",
                "late_commands_flood",
                "lost",
                "cpu_pct",
            )
            if all(r[key] is not None for r in mine)
            for vals in [[r[key] for r in mine]]
        }
    return out


def print_table(rows: list[dict]) -> None:
    head = (
        f"{'trial':>5} {'condition':>9} {'uf quiet':>8} {'uf flood':>8} {'xruns':>5} {'load %':>7} "
        f"{'DSP %':>11} {'late':>5} {'lost':>6} {'CPU %':>6}"
    )
    print(head)
    for r in rows:
        dsp = "-" if r["dsp_mean"] is None else f"{r['dsp_mean']:.1f}/{r['dsp_max']:.1f}"
        cpu = "-" if r["cpu_pct"] is None else f"{r['cpu_pct']:.1f}"
        print(
            f"{r['trial']:>5} {r['condition']:>9} {r['underflows_quiet']:>8} {r['underflows_flood']:>8} "
            f"{r['xruns_flood']:>5} {100 * r['render_load_flood']:>7.2f} {dsp:>11} {r['late_commands_flood']:>5} "
            f"{r['lost']:>6} {cpu:>6}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0, help="flood length per window")
    parser.add_argument("--quiet", type=float, default=5.0, help="quiet baseline before the flood")
    parser.add_argument("--rate", type=int, default=10_000, help="OSC messages per second")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "clip_flood.json")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as logdir:
        jackd = JackServer("bench-clips", 48000, 128, Path(logdir), driver_args=("-P", str(CHANNELS)))
        try:
            jackd.start()
            monitor = Monitor(jackd.name)
            try:
                for trial in range(1, args.trials + 1):
                    order = CONDITIONS if trial % 2 else tuple(reversed(CONDITIONS))
                    for condition in order:
                        with tempfile.TemporaryDirectory() as tmp:
                            row = run_condition(condition, args, jackd, monitor, Path(tmp))
                        row["trial"] = trial
                        rows.append(row)
                        print(f"trial {trial} {condition}: {json.dumps(row)}", file=sys.stderr)
            finally:
                monitor.close()
        finally:
            stop_all()
    print_table(rows)
    result = {
        "rows": rows,
        "summary": summary(rows),
        "settings": {
            "channels": CHANNELS,
            "clips": CLIPS,
            "rate": args.rate,
            "flood_s": args.seconds,
            "quiet_s": args.quiet,
            "jack": {"driver": "dummy", "rate": 48000, "period": 128, "playback_ports": CHANNELS},
        },
        "machine": machine_info(),
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
