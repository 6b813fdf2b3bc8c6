"""Input path benchmark (issue 24 item 2): the compiled input callback's cost, and the reader's.

    python benchmarks/bench_input.py [--blocks 20000]

* callback: time inside the PortAudio input callback (the ring's own clock, ``load_last``, taken
  around the copy into the ring), per block, at 48 kHz, 64/128/256 frames, 1/2/8 ring channels
  out of an 8-input device, as microseconds and % of the block period (p50/p99/max). The
  callback is driven through ``InputRing.run_callback``, the function PortAudio calls.
* reader: ``InputRing.read`` of what 8 blocks left (the follow worker's step), microseconds.

Prints a table and writes ``benchmarks/results/bench_input.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vibsynth.engine.input_ring import InputRing  # noqa: E402

FS = 48000.0
DEVICE_CHANNELS = 8


def bench(frames: int, channels: int, blocks: int) -> dict:
    rng = np.random.default_rng(frames * 100 + channels)
    ring = InputRing(channels, FS)
    ring.set_input_map(DEVICE_CHANNELS, list(range(channels)))
    block = rng.standard_normal((frames, DEVICE_CHANNELS)).astype(np.float32)
    cost = np.empty(blocks)
    reads = []
    for k in range(blocks):
        ring.run_callback(block)
        cost[k] = ring._ring.load_last * frames / FS
        if k % 8 == 7:
            t = time.perf_counter()
            ring.read()
            reads.append(time.perf_counter() - t)
    period = frames / FS
    assert ring.overflows == 0
    return {
        "frames": frames,
        "channels": channels,
        "callback_us_p50": 1e6 * float(np.percentile(cost, 50)),
        "callback_us_p99": 1e6 * float(np.percentile(cost, 99)),
        "callback_us_max": 1e6 * float(cost.max()),
        "callback_pct_p50": 100 * float(np.percentile(cost, 50)) / period,
        "callback_pct_p99": 100 * float(np.percentile(cost, 99)) / period,
        "read_us_p50": 1e6 * float(np.median(reads)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=20000)
    parser.add_argument("--json", default=str(Path(__file__).parent / "results" / "bench_input.json"))
    args = parser.parse_args()
    rows = [bench(frames, channels, args.blocks) for frames in (64, 128, 256) for channels in (1, 2, 8)]
    print(f"input callback at {FS:g} Hz, {DEVICE_CHANNELS}-input device, {args.blocks} blocks each")
    print(f"{'frames':>6} {'ch':>3} {'p50 us':>8} {'p99 us':>8} {'max us':>8} {'p50 %':>7} {'p99 %':>7} {'read us':>8}")
    for r in rows:
        print(
            f"{r['frames']:>6} {r['channels']:>3} {r['callback_us_p50']:>8.2f} {r['callback_us_p99']:>8.2f} "
            f"{r['callback_us_max']:>8.1f} {r['callback_pct_p50']:>7.3f} {r['callback_pct_p99']:>7.3f} "
            f"{r['read_us_p50']:>8.1f}"
        )
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"fs": FS, "device_channels": DEVICE_CHANNELS, "rows": rows}, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
