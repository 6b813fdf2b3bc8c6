"""Engine benchmarks (issue 3): render cost, bank build, control latency and underflows on JACK.

    python benchmarks/bench_engine.py [--quick] [--no-jack]
    scripts/with_jack.sh -- python benchmarks/bench_engine.py          # with the JACK parts

Prints a table and writes benchmarks/results/engine-<timestamp>.json.

* render cost: ``Engine.render_into`` per block as % of the block period (p50/p99/p99.9)
  at 48 kHz, 64/128/256 frames, 1/2/8 channels; "steady" = constant knobs, "moving" =
  a new knob target every 10 blocks (the glide path runs most of the time).
* bank build: cold (no cache) and cached, default grid (49 x 4 s x 48 kHz).
* control latency (JACK): time from ``engine.submit`` to the first captured sample that
  reflects it (JACK frame clock), for jumps from silence; goal <= 1 block + glide.
* underflows (JACK): PortAudio stream at 128 frames for 60 s (10 s with --quick) while
  a control thread floods ~10,000 commands/s through the Controller.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vibsynth.control.controller import Controller  # noqa: E402
from vibsynth.engine.bank import BankSpec, load_or_build  # noqa: E402
from vibsynth.engine.commands import SetKnob  # noqa: E402
from vibsynth.engine.engine import Engine  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402

FS = 48000


def bench_bank(cache: str) -> dict:
    basis = default_basis()
    t = time.perf_counter()
    bank, origin = load_or_build(basis, BankSpec(fs=FS), cache_dir=cache)
    cold = time.perf_counter() - t
    t = time.perf_counter()
    _, origin2 = load_or_build(basis, BankSpec(fs=FS), cache_dir=cache)
    cached = time.perf_counter() - t
    return {"cold_s": cold, "cached_s": cached, "origins": [origin, origin2], "bytes": int(bank.signals.nbytes)}, bank


def bench_render(bank, blocks: int) -> list[dict]:
    rows = []
    rng = np.random.default_rng(1)
    for channels in (1, 2, 8):
        for frames in (64, 128, 256):
            for mode in ("steady", "moving"):
                e = Engine(bank, channels=channels, initial_intensity=0.5, max_block=frames)
                out = np.zeros((frames, channels), dtype=np.float32)
                for _ in range(50):
                    e.render_into(out)
                times = np.empty(blocks)
                for n in range(blocks):
                    if mode == "moving" and n % 10 == 0:
                        e.submit(SetKnob("balance", float(rng.uniform(-3, 3))))
                        e.submit(SetKnob("intensity", float(rng.uniform(0.1, 1))))
                    t = time.perf_counter()
                    e.render_into(out)
                    times[n] = time.perf_counter() - t
                pct = 100 * times * FS / frames
                p50, p99, p999 = np.percentile(pct, [50, 99, 99.9])
                rows.append(
                    {
                        "channels": channels,
                        "frames": frames,
                        "mode": mode,
                        "p50_pct": p50,
                        "p99_pct": p99,
                        "p999_pct": p999,
                    }
                )
    return rows


def jack_parts(bank, seconds: float) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.e2e.jackutil import JackCapture, jack_server_available, portaudio_output_ports
    from vibsynth.engine.outputs import SoundDeviceOutput

    ok, reason = jack_server_available()
    if not ok:
        return {"skipped": reason}
    result: dict = {}
    # Control latency: silent stream, jump to full intensity, find the first non-zero captured sample.
    engine = Engine(bank, channels=1, glide_s=0.0, max_block=128)
    output = SoundDeviceOutput(engine, host_api="JACK", block_size=128)
    output.open()
    latencies = []
    with JackCapture(0.5) as cap:
        cap.connect(portaudio_output_ports(cap.client)[:1])
        output.start()
        time.sleep(0.3)
        for _trial in range(20):
            engine.submit(SetKnob("intensity", 0.0, glide_s=0.0))
            time.sleep(0.05)
            cap.reset()
            cap.arm()
            time.sleep(0.05)
            t_submit = cap.frame_time_now()
            engine.submit(SetKnob("intensity", 0.8, glide_s=0.0))
            cap.wait()
            nz = np.flatnonzero(cap.data[:, 0])
            if nz.size and cap.start_frame is not None:
                latencies.append(cap.start_frame + int(nz[0]) - t_submit)
        output.stop()
    lat = np.array(latencies) / FS * 1000
    result["latency_ms"] = {
        "median": float(np.median(lat)),
        "max": float(lat.max()),
        "n": int(lat.size),
        "block_ms": 128 / FS * 1000,
    }
    # Underflows under a control flood through the Controller.
    engine = Engine(bank, channels=2, initial_intensity=0.5, max_block=128)
    controller = Controller(engine)
    output = SoundDeviceOutput(engine, host_api="JACK", block_size=128)
    output.start()
    time.sleep(0.5)
    before = output.stats.underflows
    stop = threading.Event()
    sent = [0]

    def flood() -> None:
        rng = np.random.default_rng(2)
        period = 1e-4  # 10,000 commands/s target
        next_t = time.perf_counter()
        while not stop.is_set():
            controller.set_knob("balance", float(rng.uniform(-3, 3)), source="bench")
            sent[0] += 1
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)

    thread = threading.Thread(target=flood, daemon=True)
    t0 = time.perf_counter()
    thread.start()
    time.sleep(seconds)
    stop.set()
    thread.join()
    elapsed = time.perf_counter() - t0
    result["flood"] = {
        "seconds": elapsed,
        "commands_per_s": sent[0] / elapsed,
        "underflows": output.stats.underflows - before,
        "startup_underflows": before,
        "load_peak_pct": 100 * engine.stats.load_peak,
    }
    output.stop()
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="short runs (2,000 blocks; 10 s flood)")
    parser.add_argument("--no-jack", action="store_true", help="skip the JACK measurements")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        bank_result, bank = bench_bank(cache)
    print(
        f"bank build: cold {bank_result['cold_s']:.2f} s, cached {bank_result['cached_s']:.2f} s "
        f"({bank_result['bytes'] / 1e6:.0f} MB)"
    )
    rows = bench_render(bank, 2000 if args.quick else 20000)
    print(f"{'ch':>3} {'frames':>6} {'mode':>7} {'p50 %':>7} {'p99 %':>7} {'p99.9 %':>8}")
    for r in rows:
        print(
            f"{r['channels']:>3} {r['frames']:>6} {r['mode']:>7} "
            f"{r['p50_pct']:7.2f} {r['p99_pct']:7.2f} {r['p999_pct']:8.2f}"
        )
    jack = {"skipped": "--no-jack"} if args.no_jack else jack_parts(bank, 10.0 if args.quick else 60.0)
    if "skipped" in jack:
        print(f"JACK measurements skipped: {jack['skipped']}")
    else:
        lat = jack["latency_ms"]
        print(
            f"control latency: median {lat['median']:.2f} ms, max {lat['max']:.2f} ms "
            f"(block {lat['block_ms']:.2f} ms, glide 0; n={lat['n']})"
        )
        fl = jack["flood"]
        print(
            f"flood: {fl['commands_per_s']:.0f} commands/s for {fl['seconds']:.0f} s -> "
            f"{fl['underflows']} underflows (start-up {fl['startup_underflows']}), peak load {fl['load_peak_pct']:.0f}%"
        )
    out_dir = Path(__file__).resolve().parent / "results"
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"engine-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.write_text(
        json.dumps(
            {
                "bank": bank_result,
                "render": rows,
                "jack": jack,
                "quick": args.quick,
                "cpus": os.cpu_count(),
                "load": os.getloadavg(),
            },
            indent=2,
        )
    )
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
