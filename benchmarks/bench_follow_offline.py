"""Follow offline: speed (x real time on one core) and peak memory of ``render --follow`` and ``clip from-audio``.

Each case runs the command line in its own child process pinned to one core (this process's
CPU affinity, inherited; BLAS/OpenMP threads limited to 1), which reports its peak RSS
(``ru_maxrss``), the wall time of ``main()`` (imports excluded; the bank from a warm cache)
and its CPU time (user + system, imports included): x real time is given both ways, the CPU
one being what a quiet core would do on a shared machine. Input: generated noise, 48 kHz mono
16-bit, whose level moves by up to 20 dB every 0.5 s with a click every 2 s (written block by
block: the generator holds no more than the renderer does). Output: 48 kHz mono float32.

* ``render-vibration`` / ``render-audio``: ``vibsynth render --follow IN -o OUT --follow-mode M``
* ``clip-vibration`` / ``clip-audio``: ``vibsynth clip from-audio IN -o OUT.yaml --mode M``
  (a clip holds at most 10 minutes: 60 and 600 s only)

Lengths: 60 and 600 s; ``--long`` adds 3600 s (an hour: the flat-memory check is the RSS of
600 s against 3600 s). Prints a table and writes ``benchmarks/results/bench_follow_offline.json``.

Run: ``python benchmarks/bench_follow_offline.py [--long] [--seconds 60,600] [--kinds render-vibration]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_render import measure, run_case, save_run, write_config  # noqa: E402

from vibsynth.formats.wav_stream import WavStreamWriter  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "bench_follow_offline.json"
KINDS = ("render-vibration", "render-audio", "clip-vibration", "clip-audio")
RATE = 48000
#: The issue's target: at least this many seconds of input per second of wall time, on one core.
TARGET_X = 20.0


def write_input(path: Path, seconds: float, seed: int = 1) -> None:
    """Noise whose level steps every 0.5 s (within 20 dB) with a click every 2 s, written in 1 s blocks."""
    rng = np.random.default_rng(seed)
    with WavStreamWriter(path, RATE, 1, sample_format="pcm16", frames=int(seconds * RATE)) as w:
        for k in range(int(seconds)):
            gains = 0.05 * 10 ** (-rng.uniform(0, 20, 2) / 20)
            block = rng.standard_normal(RATE) * np.repeat(gains, RATE // 2)
            if k % 2 == 0:
                block[RATE // 4] = 0.9
            w.write(block)
        w.close()


def case_args(kind: str, src: Path, out_dir: Path, config: Path) -> tuple[list[str], Path]:
    what, mode = kind.split("-")
    if what == "render":
        out = out_dir / "out.wav"
        return [
            "render",
            "--follow",
            str(src),
            "--follow-mode",
            mode,
            "--config",
            str(config),
            "-q",
            "-o",
            str(out),
        ], out
    out = out_dir / "out.yaml"
    return ["clip", "from-audio", str(src), "--mode", mode, "--config", str(config), "-q", "-o", str(out)], out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--long", action="store_true", help="also 3600 s (renders only)")
    parser.add_argument("--seconds", help="comma-separated lengths (default 60,600[,3600])")
    parser.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated subset of {','.join(KINDS)}")
    parser.add_argument("--label", default="follow offline", help="name of this run in the JSON")
    parser.add_argument("--json", type=Path, default=RESULTS)
    args = parser.parse_args()
    lengths = [float(s) for s in args.seconds.split(",")] if args.seconds else [60.0, 600.0] + [3600.0] * args.long
    kinds = [k for k in args.kinds.split(",") if k]
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    pinned = hasattr(os, "sched_setaffinity")
    if pinned:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # children inherit one core
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench_follow_offline-") as tmp:
        work = Path(tmp)
        config = write_config(work)
        warm = work / "warm.wav"
        write_input(warm, 1.0)
        run_case(
            ["render", "--follow", str(warm), "--config", str(config), "-q", "-o", str(work / "w.wav")], None, work
        )
        for seconds in lengths:
            src = work / f"in-{seconds:g}.wav"
            write_input(src, seconds)
            for kind in kinds:
                if kind.startswith("clip") and seconds > 600:
                    continue
                argv, out = case_args(kind, src, work, config)
                result = measure(kind, seconds, argv, out, None, work)
                if "wall_s" in result and result.get("code") == 0:
                    result["x_real_time"] = round(seconds / result["wall_s"], 1)
                    result["x_real_time_cpu"] = round(seconds / result["cpu_s"], 1)
                rows.append(result)
                status = f"ERROR {result['error']}" if result.get("code") else ""
                print(
                    f"{kind:17s} {seconds:6.0f} s  x{result.get('x_real_time', float('nan')):6.1f} wall  "
                    f"x{result.get('x_real_time_cpu', float('nan')):6.1f} cpu  "
                    f"peak RSS {result.get('peak_rss_mb', float('nan')):7.1f} MB {status}",
                    flush=True,
                )
            src.unlink()
    save_run(
        args.json,
        args.label,
        {
            "settings": f"input {RATE} Hz mono pcm16 noise (level steps, clicks); output {RATE} Hz float32; "
            f"{'one core (CPU affinity)' if pinned else 'not pinned'}, 1 BLAS thread; bank from a warm cache",
            "target_x_real_time": TARGET_X,
            "cases": rows,
        },
    )
    print(f"\n{'kind':17s} {'seconds':>8s} {'x rt (wall)':>12s} {'x rt (cpu)':>11s} {'peak RSS MB':>12s}")
    for r in rows:
        x = f"{r['x_real_time']:.1f}" if "x_real_time" in r else "-"
        xc = f"{r['x_real_time_cpu']:.1f}" if "x_real_time_cpu" in r else "-"
        rss = f"{r['peak_rss_mb']:.0f}" if "peak_rss_mb" in r else "-"
        note = f"  ({r['error']})" if r.get("code") else ""
        print(f"{r['kind']:17s} {r['seconds']:8.0f} {x:>12s} {xc:>11s} {rss:>12s}{note}")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
