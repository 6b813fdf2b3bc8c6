"""OSC on a busy machine: does ``vibsynth serve`` lose UDP messages when every core is taken?

    python benchmarks/bench_osc_busy.py [--seconds 20] [--hogs 0 20] [--rate 10000]

The soak (benchmarks/bench_soak.py) lost 0.37 % of its messages at a load average of 15-20. This
isolates that case: ``serve`` on the null output (``vibsynth serve --output null``, one channel)
receives a flood of ``--rate`` messages/s (``/vibsynth/ch/1/intensity`` and ``balance``
alternating, 1 ms bursts, from a child process) with a ``/vibsynth/ch/1/play impact`` every
``--play-every`` seconds (a message for the Python handler; 0 = none), while ``--hogs`` processes
spin on the CPU (``while True: pass``, normally scheduled). Each row is one run of
``--seconds``.

It reports what was sent, what serve counted (``packets`` in /status), what the kernel dropped
because the socket's buffer was full (``RcvbufErrors`` of /proc/net/snmp, Linux; nothing else on
the machine receives UDP meanwhile), serve's own ``queue_full`` (messages it dropped because
Python was 32,768 behind: counted, docs/osc.md) and ``fast_path``; serve's ``packets`` are read
before and after, so its start-up pings and the /status requests do not count.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_osc import write_json  # noqa: E402
from bench_peers import machine_info  # noqa: E402
from bench_soak import flood  # noqa: E402

from tests.e2e.oscclient import OscClient  # noqa: E402
from tests.e2e.test_osc_e2e import start_serve, stop_serve  # noqa: E402


def kernel_udp_drops() -> int | None:
    """The kernel's count of UDP datagrams dropped for a full receive buffer (Linux), or None."""
    try:
        rows = [line.split() for line in Path("/proc/net/snmp").read_text().splitlines() if line.startswith("Udp:")]
    except OSError:
        return None
    return int(dict(zip(rows[0][1:], rows[1][1:]))["RcvbufErrors"])


def hog() -> None:
    """A process that takes a core whenever the scheduler gives it one."""
    while True:
        pass


def one_run(hogs: int, seconds: float, rate: int, play_every: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-osc-busy-") as tmp:
        proc, port = start_serve(Path(tmp))
        client = OscClient(port)
        try:
            spinners = [mp.Process(target=hog, daemon=True) for _ in range(hogs)]
            for spinner in spinners:
                spinner.start()
            running, stop, sent = mp.Event(), mp.Event(), mp.Value("q", 0)
            flooder = mp.Process(target=flood, args=(port, rate, running, stop, sent))
            flooder.start()
            status0 = client.status()
            before = kernel_udp_drops()
            plays = 0
            running.set()
            start = time.monotonic()
            while time.monotonic() - start < seconds:
                if play_every > 0:
                    client.send("/vibsynth/ch/1/play", "impact", 1.0, 1.0, 1, types="sffi")
                    plays += 1
                time.sleep(play_every if play_every > 0 else 0.1)
            running.clear()
            stop.set()
            flooder.join(10.0)
            for spinner in spinners:
                spinner.terminate()
            for spinner in spinners:
                spinner.join(5.0)
            time.sleep(1.0)  # serve reads what is left
            after = kernel_udp_drops()
            status = client.status()
        finally:
            client.close()
            stop_serve(proc)
    total = int(sent.value) + plays  # the flood and the plays
    counted = int(status["packets"]) - int(status0["packets"]) - 1  # without the second /status request
    return {
        "hogs": hogs,
        "seconds": seconds,
        "sent": total,
        "counted": counted,
        "lost": total - counted,
        "kernel_drops": None if before is None or after is None else after - before,
        "queue_full": int(status.get("queue_full", 0)),
        "fast_path": int(status["fast_path"]),
        "plays": plays,
    }


def print_table(rows: list[dict[str, Any]]) -> None:
    print(f"{'hogs':>5} {'sent':>9} {'counted':>9} {'lost':>7} {'lost %':>7} {'kernel drops':>13} {'queue_full':>11}")
    for r in rows:
        print(
            f"{r['hogs']:>5} {r['sent']:>9} {r['counted']:>9} {r['lost']:>7} {100 * r['lost'] / r['sent']:>7.3f}"
            f" {r['kernel_drops'] if r['kernel_drops'] is not None else '-':>13} {r['queue_full']:>11}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0, help="length of each run")
    parser.add_argument("--hogs", type=int, nargs="+", default=[0, 20], help="spinning processes, one run each")
    parser.add_argument("--rate", type=int, default=10_000, help="OSC flood, messages per second")
    parser.add_argument("--play-every", type=float, default=0.25, help="a /play every this many s (0: none)")
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "osc_busy.json")
    args = parser.parse_args(argv)
    if not 0.5 <= args.seconds <= 3600 or any(not 0 <= h <= 256 for h in args.hogs) or not 100 <= args.rate <= 100_000:
        parser.error("--seconds 0.5..3600, --hogs 0..256, --rate 100..100000")
    rows = [one_run(h, args.seconds, args.rate, args.play_every) for h in args.hogs]
    result = {"machine": machine_info(), "rate": args.rate, "play_every": args.play_every, "runs": rows}
    print_table(rows)
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
