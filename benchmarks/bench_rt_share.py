#!/usr/bin/env python3
"""Real-time share benchmark (issue 33): whose are the underflows under a 10,000 messages/s flood?

    python benchmarks/bench_rt_share.py                         # 4 rounds of 10 s windows, ~10 min
    python benchmarks/bench_rt_share.py --rounds 2 --seconds 5  # a quick look
    python benchmarks/bench_rt_share.py --only vibsynth,vibsynth-nofifo

The end-to-end tests count PortAudio's underflows during a flood, and on a fresh 2-core VM they
saw 7-11 in 10 s where the quiet machine saw 0-2. PortAudio counts every xrun of the JACK server,
including the dummy driver's own late wake-ups, so that count mixes the machine's noise with the
product's share. This benchmark separates them, on the same machine in the same run:

* **jack alone**: a private JACK server (dummy driver, 48 kHz / 128, ``-R``) with only the
  watching client: how often the driver itself wakes late here (its xrun callbacks and
  ``JackTimedDriver::Process XRun`` lines);
* per target, **quiet** (streaming a loud texture, no control traffic) and **flood** (the same,
  plus ``--rate`` OSC messages/s in 1 ms bursts from a separate sender process):
  ``vibsynth`` (``serve`` through PortAudio's JACK host API, its UDP receive loop at SCHED_FIFO 1,
  the default), ``vibsynth-nofifo`` (the same with ``osc.receive_priority: 0``), ``scsynth``
  (Debian ``supercollider-server``, ``/n_set`` of a 30-band filter bank) and ``pyo`` (PyPI,
  ``OscReceive`` read in its audio thread): the peers and the job are bench_peers.py's.

Every target runs on its own private JACK server, all of them streaming for the whole run; the
windows are taken in rounds, each round every condition once in a fresh seeded random order, so
the machine's drifting load hits every condition alike. Per window: the server's xrun callbacks,
the driver's late wake-ups, the cycles in which jackd reports **the target's own client** not
finished (``JackEngine::XRun: client = <target> was not finished``: the target's share), and for
vibsynth its ``/status`` underflows and the messages it received. Printed: per condition the
median and maximum per 10 s and the totals; written: benchmarks/results/rt_share.json (machine,
settings, every window).

Needs jackd2 and JACK-Client (as the e2e tests); a peer that is not installed is skipped with a
message. Everything is bounded (``--timeout``) and every process it starts is stopped on exit.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_peers as bp  # noqa: E402 - the peers, JACK servers, agents and flood sender

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_JSON = ROOT / "benchmarks" / "results" / "rt_share.json"
TARGETS = ("vibsynth", "vibsynth-nofifo", "scsynth", "pyo")
ALONE = "jack alone"
#: Per-window figures summarised (absent ones are skipped).
FIGURES = ("xrun_callbacks", "driver_late_wakeups", "target_late_cycles", "status_underflows")


def _args_for_peers(ns: argparse.Namespace) -> argparse.Namespace:
    """The namespace bench_peers' PeerRun and targets read."""
    return argparse.Namespace(
        seconds=ns.seconds,
        rate=ns.rate,
        jack_rate=48000,
        jack_period=128,
        warmup=2.0,
        baseline=0.0,
        vibsynth_flood="balance",
        vibsynth_src_dir=None,
        vibsynth_source="working tree" + bp._git_describe(),
        vibsynth_ref=None,
        trials=0,
        gap=0.05,
        latency_clock="wall",
    )


def flood_window(run: bp.PeerRun, seconds: float, rate: int, tmp: Path) -> dict:
    """One window of ``run``'s target under the flood, with what the sender sent."""
    sender = bp.start_sender(run.target, rate, seconds + 30, tmp)
    time.sleep(0.5)
    if sender.poll() is not None:
        raise RuntimeError(f"flood sender exited: {bp.stop_sender(sender)}")
    try:
        out = bp.measure_window(run, seconds, sender)
    finally:
        out_sender = bp.stop_sender(sender)
    out["sender"] = out_sender
    return out


def summarise(windows: list[dict], seconds: float) -> dict:
    """Per figure: per-window values, median and max per 10 s, total."""
    out: dict = {"windows": len(windows)}
    for key in FIGURES:
        having = [w for w in windows if w.get(key) is not None]
        if not having:
            continue
        values = [w[key] for w in having]
        per10 = [10.0 * w[key] / max(w["seconds"], 1e-9) for w in having]
        out[key] = {
            "values": values,
            "median_per_10s": float(np.median(per10)),
            "max_per_10s": float(np.max(per10)),
            "total": int(np.sum(values)),
        }
    if windows:
        out["cpu_pct_median"] = float(np.median([w.get("cpu_pct") or 0.0 for w in windows]))
        out["machine_busy_pct_median"] = float(np.median([w["machine_busy_pct_of_all_cores"] for w in windows]))
    return out


def print_table(summary: dict, seconds: float) -> None:
    cols = ("xrun_callbacks", "driver_late_wakeups", "target_late_cycles", "status_underflows")
    heads = ("server xruns", "driver late", "target late", "underflows")
    print(f"\nper {10:g} s (median / max over the windows of {seconds:g} s); totals")
    print(f"{'condition':28s} " + " ".join(f"{h:>18s}" for h in heads) + f" {'target CPU %':>13s}")
    for name, s in summary.items():
        cells = []
        for c in cols:
            f = s.get(c)
            cells.append(f"{f['median_per_10s']:5.1f} / {f['max_per_10s']:5.1f} ({f['total']:3d})" if f else "-")
        print(f"{name:28s} " + " ".join(f"{c:>18s}" for c in cells) + f" {s.get('cpu_pct_median', 0.0):13.1f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=4, help="rounds of windows (default 4)")
    parser.add_argument("--seconds", type=float, default=10.0, help="window length (default 10)")
    parser.add_argument("--rate", type=int, default=10000, help="flood rate, OSC messages/s (default 10000)")
    parser.add_argument("--only", default=",".join(TARGETS), help="comma-separated subset of: " + ", ".join(TARGETS))
    parser.add_argument("--seed", type=int, default=0, help="seed of the window order (default 0)")
    parser.add_argument("--timeout", type=float, default=None, help="hard bound on the run, s")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    args = parser.parse_args(argv)
    targets = [t.strip() for t in args.only.split(",") if t.strip()]
    unknown = [t for t in targets if t not in TARGETS]
    if unknown or args.rounds < 1 or args.seconds <= 0:
        parser.error(f"unknown target(s) {unknown}" if unknown else "--rounds >= 1 and --seconds > 0")
    conditions = 1 + 2 * len(targets)
    timeout = args.timeout or 2 * (len(targets) * 40 + args.rounds * conditions * (args.seconds + 2)) + 120

    def on_alarm(*_: object) -> None:
        raise bp.BenchTimeout(f"run exceeded --timeout {timeout:.0f} s")

    def on_term(*_: object) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGALRM, on_alarm)
    signal.signal(signal.SIGTERM, on_term)
    signal.alarm(int(timeout))
    peer_args = _args_for_peers(args)
    gains, _origin = bp.band_gains()
    result: dict = {
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": bp.machine_info(),
        "settings": {
            "rounds": args.rounds,
            "seconds": args.seconds,
            "flood_rate": args.rate,
            "jack": "jackd -R -d dummy -r 48000 -p 128 (JACK's default asynchronous mode), one server per target",
            "seed": args.seed,
            "vibsynth_source": peer_args.vibsynth_source,
        },
        "skipped": {},
        "windows": [],
    }
    print(
        f"bench_rt_share: {ALONE}, {', '.join(targets)}; {args.rounds} rounds of {args.seconds:g} s windows; flood "
        f"{args.rate}/s; load {os.getloadavg()[0]:.2f}; bound {timeout:.0f} s",
        flush=True,
    )
    status = 0
    runs: list[bp.PeerRun] = []
    alone = alone_mon = None
    try:
        with tempfile.TemporaryDirectory(prefix="bench-rt-share-") as tmpdir:
            tmp = Path(tmpdir)
            alone = bp.JackServer("bench-rt-alone", 48000, 128, tmp)
            alone.start()
            alone_mon = bp.JackAgent(alone, tmp)
            for peer in targets:
                missing = bp.peer_missing(peer)
                if missing:
                    print(f"  {peer}: SKIPPED: {missing}", flush=True)
                    result["skipped"][peer] = missing
                    continue
                run = bp.PeerRun(peer, peer_args, tmp, gains)
                print(f"  {peer}: starting", flush=True)
                try:
                    run.start()
                except Exception as exc:  # noqa: BLE001 - a peer that fails is reported, the rest run
                    run.fail(exc)
                    result["skipped"][peer] = run.entry.get("error", str(exc))
                    continue
                run.target.set_loud(True)
                runs.append(run)
            rng = np.random.default_rng(args.seed)
            plan: list[tuple[str, bp.PeerRun | None, str]] = [(ALONE, None, "alone")]
            plan += [(f"{run.peer} {kind}", run, kind) for run in runs for kind in ("quiet", "flood")]
            for r in range(args.rounds):
                for k in rng.permutation(len(plan)):
                    name, run, kind = plan[int(k)]
                    if run is None:
                        w = bp.baseline(alone, alone_mon, args.seconds)
                    elif kind == "quiet":
                        w = bp.measure_window(run, args.seconds, None)
                    else:
                        w = flood_window(run, args.seconds, args.rate, tmp)
                    w.update(condition=name, round=r)
                    result["windows"].append(w)
                    print(
                        f"  round {r + 1}/{args.rounds} {name:24s} xruns {w['xrun_callbacks']:3d} driver late "
                        f"{w['driver_late_wakeups']:3d} target late {w.get('target_late_cycles', 0):3d} underflows "
                        f"{w.get('status_underflows', '-')}",
                        flush=True,
                    )
            for run in runs:
                result[f"{run.peer}_version"] = run.entry.get("version")
    except (KeyboardInterrupt, bp.BenchTimeout) as exc:
        print(f"\nbench_rt_share: interrupted ({exc or 'Ctrl-C or SIGTERM'}); stopping everything", file=sys.stderr)
        status = 3
    finally:
        signal.alarm(0)
        for run in runs:
            try:
                run.stop()
            except Exception as exc:  # noqa: BLE001
                print(f"bench_rt_share: stopping {run.peer}: {exc}", file=sys.stderr)
        if alone_mon is not None:
            alone_mon.close()
        if alone is not None:
            alone.stop()
        bp.stop_all()
    names = [ALONE] + [f"{run.peer} {kind}" for run in runs for kind in ("quiet", "flood")]
    summary = {n: summarise([w for w in result["windows"] if w["condition"] == n], args.seconds) for n in names}
    result["summary"] = summary
    print_table(summary, args.seconds)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(bp.compact_json(result), encoding="utf-8")
    print(f"\nJSON: {args.json}")
    return status


if __name__ == "__main__":
    sys.exit(main())
