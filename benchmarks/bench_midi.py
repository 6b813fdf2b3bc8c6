"""MIDI benchmark on JACK: message -> output latency, and a sustained 1,000 messages/s flood.

Run with a JACK server (the script is JACK-specific; the product takes the backend from MIDO_BACKEND):

    scripts/with_jack.sh -- python benchmarks/bench_midi.py [--notes 200] [--flood-seconds 10]

Setup: the MIDI adapter exactly as ``vibsynth serve --midi-virtual`` creates it, a
real Controller and Engine (48 kHz), rendered from a JACK process callback into a
JACK audio port; a second JACK MIDI client in this process sends to ``vibsynth``.

* latency: note-on sent -> the first JACK period whose rendered output is
  non-zero (wall clock at the start of that process callback). JACK's own
  output buffering (``period`` frames per buffer) comes on top.
* flood: 1,000 CC messages/s (CC 74 and CC 11 alternating) for N seconds;
  counts JACK xruns, engine blocks rendered late (callback time > period) and
  messages received.

Prints a table and writes ``benchmarks/results/midi.json``.
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MIDO_BACKEND", "mido.backends.rtmidi/UNIX_JACK")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jack  # noqa: E402
import mido  # noqa: E402

from vibsynth.control.controller import Controller  # noqa: E402
from vibsynth.control.midi import adapter as midi  # noqa: E402
from vibsynth.engine.bank import BankSpec, build_bank  # noqa: E402
from vibsynth.engine.engine import Engine  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402
from vibsynth.settings.config import default_config_data  # noqa: E402
from vibsynth.settings.typed import settings_of  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--notes", type=int, default=200)
    ap.add_argument("--flood-seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=int, default=1000, help="flood messages per second")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "midi.json"))
    opts = ap.parse_args()
    if os.environ.get("BENCH_DEBUG"):
        faulthandler.dump_traceback_later(float(os.environ["BENCH_DEBUG"]), exit=True)

    client = jack.Client("vibsynth-bench")
    fs, period = client.samplerate, client.blocksize
    engine = Engine(
        build_bank(default_basis(), BankSpec(fs=fs, loop_seconds=1.0, levels=15)),
        channels=1,
        ceiling_db=-24.0,
        max_block=max(period, 256),
    )
    controller = Controller(engine)
    data = default_config_data()
    data["midi"].update(release_ms=0.0, attack_ms=0.0)
    parser = argparse.ArgumentParser()
    midi.add_arguments(parser)
    server = midi.create(settings_of(data), parser.parse_args(["--midi-virtual"]), controller, None)
    if server is None:
        print("bench_midi: no MIDI backend (is JACK running? MIDO_BACKEND?)", file=sys.stderr)
        return 2
    server.start()

    port = client.outports.register("out")
    state = {"waiting": False, "hit": None, "late": 0, "blocks": 0, "xruns": 0}
    budget = period / fs

    @client.set_process_callback
    def process(frames: int) -> None:
        t = time.perf_counter()
        block = engine.render(frames)
        port.get_array()[:] = block[:, 0]
        if state["waiting"] and block[:, 0].any():
            state["hit"], state["waiting"] = t, False
        state["blocks"] += 1
        if time.perf_counter() - t > budget:
            state["late"] += 1

    @client.set_xrun_callback
    def xrun(delay: float) -> None:
        state["xruns"] += 1

    # Open every JACK client before the Python process callback runs: creating a JACK
    # client while holding the GIL deadlocks against an in-process Python callback.
    name = next(n for n in mido.get_output_names() if n.endswith("vibsynth"))
    out = mido.open_output(name)
    client.activate()
    time.sleep(0.5)

    rng = np.random.default_rng(7)
    latencies = []
    for _ in range(opts.notes):
        state["hit"] = None
        state["waiting"] = True
        t0 = time.perf_counter()
        out.send(mido.Message("note_on", note=60, velocity=127))
        while state["hit"] is None and time.perf_counter() - t0 < 1.0:
            time.sleep(0.0002)
        if state["hit"] is not None:
            latencies.append(state["hit"] - t0)
        out.send(mido.Message("note_off", note=60))
        time.sleep(0.03 + 0.02 * rng.random())  # release (0 ms) + random phase against the period
    lat_ms = np.array(latencies) * 1000.0

    # flood
    before = dict(state)
    received0 = server.received
    n_msgs = int(opts.flood_seconds * opts.rate)
    out.send(mido.Message("note_on", note=60, velocity=100))
    t0 = time.perf_counter()
    for i in range(n_msgs):
        target = t0 + i / opts.rate
        while (d := target - time.perf_counter()) > 0:
            time.sleep(min(d, 0.0005))
        cc = 74 if i % 2 else 11
        out.send(mido.Message("control_change", control=cc, value=int(64 + 63 * np.sin(i / 50.0))))
    sent_s = time.perf_counter() - t0
    time.sleep(0.3)
    out.send(mido.Message("note_off", note=60))
    flood = {
        "messages": n_msgs,
        "seconds": round(sent_s, 3),
        "rate_msgs_per_s": round(n_msgs / sent_s, 1),
        "received": server.received - received0 - 1,
        "xruns": state["xruns"] - before["xruns"],
        "late_blocks": state["late"] - before["late"],
        "blocks": state["blocks"] - before["blocks"],
    }
    out.close()
    client.deactivate()
    client.close()
    server.stop()

    result = {
        "backend": os.environ["MIDO_BACKEND"],
        "fs": fs,
        "period": period,
        "latency_ms": {
            "n": int(lat_ms.size),
            "median": round(float(np.median(lat_ms)), 3) if lat_ms.size else None,
            "p99": round(float(np.percentile(lat_ms, 99)), 3) if lat_ms.size else None,
            "max": round(float(lat_ms.max()), 3) if lat_ms.size else None,
            "period_ms": round(1000.0 * period / fs, 3),
        },
        "flood": flood,
    }
    print(f"{'metric':38s} value")
    print(f"{'JACK rate / period':38s} {fs} Hz / {period} frames ({result['latency_ms']['period_ms']} ms)")
    lm = result["latency_ms"]
    print(f"{'note-on -> output latency median':38s} {lm['median']} ms (n={lm['n']})")
    print(f"{'note-on -> output latency p99':38s} {lm['p99']} ms (max {lm['max']})")
    print(f"{'flood rate':38s} {flood['rate_msgs_per_s']} msgs/s for {flood['seconds']} s")
    print(f"{'flood messages received':38s} {flood['received']} / {flood['messages']}")
    print(f"{'flood JACK xruns':38s} {flood['xruns']}")
    print(f"{'flood late render blocks':38s} {flood['late_blocks']} / {flood['blocks']}")
    Path(opts.out).parent.mkdir(parents=True, exist_ok=True)
    Path(opts.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {opts.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
