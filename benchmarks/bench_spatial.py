#!/usr/bin/env python3
"""Touch sources benchmark: OSC position message -> audible change (latency), and the mixer's cost.

    scripts/with_jack.sh -- python benchmarks/bench_spatial.py [--trials 40]

Latency (needs JACK): ``vibsynth serve`` streams 4 channels on a line 10 cm apart through
PortAudio into JACK; a JACK client records channels 1 and 2. A source (linear roll-off,
radius 10 cm) sits on channel 1, so channel 2 is silent; each trial sends one
``/vibsynth/source/1/pos`` to channel 2's position (noting the wall clock at the send),
then moves it back. Measured on the captured samples: **onset**, send -> first non-zero sample
on channel 2 (the change starts to be felt), and **done**, send -> channel 1's last non-zero
sample (the move is complete: channel 1 released and faded out). Once with the default
position glide (``sources.glide_ms: 20``) and once with 0 (a jump; the channels still glide
over one mix period, ``sources.update_ms: 10``, so there is no click).

Times are on the wall clock: a captured sample's time is when the JACK cycle that delivered it
ran, plus its place in the cycle (when it was rendered; a sound card plays it its output latency
later). JACK's frame clock is not used: on a loaded machine the dummy driver runs late and that
clock drifts from the wall clock by milliseconds. The JSON records the load average; a trial is
left out when its channels were not in the expected state around it.

Cost (no audio): the mix of n sources (1, 4, 16) on the shipped glove (6 actuators) and vest
(16), and a 64-actuator grid, per mix in microseconds; OSC position messages handled per second
with a running mixer (a flood coalesces into one mix per update).

Prints tables and writes JSON to benchmarks/results/spatial.json.
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

from tests.control.osc.fakes import FakePeer, make_controller  # noqa: E402
from tests.e2e.test_osc_e2e import Client, jack_available, start_serve, stop_serve  # noqa: E402
from vibsynth.control.osc.codec import encode_message  # noqa: E402
from vibsynth.control.osc.handler import OscHandler  # noqa: E402
from vibsynth.control.spatial.adapter import build_mixer  # noqa: E402
from vibsynth.control.spatial.sources import SourceView  # noqa: E402
from vibsynth.formats.files import atomic_write_text  # noqa: E402
from vibsynth.settings.config import load_config  # noqa: E402
from vibsynth.settings.layouts import Layout, load_layout  # noqa: E402
from vibsynth.settings.models_config import ChannelPosition  # noqa: E402

LINE = "audio:\n  channels: 4\nlayout:\n" + "".join(f"  {c + 1}: {{x: {0.1 * c:.1f}, y: 0.0}}\n" for c in range(4))
SILENT = 1e-7


def timed_capture(seconds: float, n_ports: int):
    """A JACK capture that also notes, for every cycle, its first sample and the wall clock (monotonic) then."""
    from tests.e2e.jackutil import JackCapture

    class TimedCapture(JackCapture):
        def __init__(self) -> None:
            self.cycle_first: list[int] = []  # appended on JACK's thread, read after the capture
            self.cycle_time: list[float] = []
            super().__init__(seconds, n_ports=n_ports)

        def _process(self, frames: int) -> None:
            first = self.frames_captured
            super()._process(frames)
            if self.frames_captured > first:
                self.cycle_first.append(first)
                self.cycle_time.append(time.monotonic())

    return TimedCapture()


def latency_trials(port: int, trials: int) -> tuple[list[float], list[float], dict[str, int]]:
    """(onset, done) latencies in seconds on the wall clock, and the trials left out (why).

    A captured sample's time is the wall-clock time of the JACK cycle that delivered it plus its
    place in the cycle: the moment it was rendered (a sound card plays it its output latency
    later). JACK's own frame clock is not used: on a loaded machine the dummy driver runs late
    and that clock drifts from the wall clock by milliseconds.
    """
    from tests.e2e.jackutil import portaudio_output_ports

    client = Client(port)
    for address, args in (
        ("/vibsynth/source/1/texture", (0.8, 0.0)),
        ("/vibsynth/source/1/radius", (0.1,)),
        ("/vibsynth/source/1/rolloff", ("linear",)),
        ("/vibsynth/source/1/pos", (0.0, 0.0)),
        ("/vibsynth/source/1/on", (1,)),
    ):
        client.send(address, *args)
    gap_s = 0.25
    sends: list[tuple[float, float]] = []  # wall clock of the move to channel 2 and of the move back
    with timed_capture(trials * 2 * gap_s + 2.0, 2) as cap:
        cap.connect(portaudio_output_ports(cap.client)[:2])
        cap.arm()
        time.sleep(0.5)
        for _ in range(trials):
            there = time.monotonic()
            client.send("/vibsynth/source/1/pos", 0.1, 0.0)
            time.sleep(gap_s)
            sends.append((there, time.monotonic()))
            client.send("/vibsynth/source/1/pos", 0.0, 0.0)
            time.sleep(gap_s)
        assert cap.wait(), "capture did not complete"
        data, rate = cap.data.copy(), cap.rate
        firsts, times = np.asarray(cap.cycle_first), np.asarray(cap.cycle_time)
    client.close()

    def index_at(t: float) -> int:
        """The first sample rendered at or after wall time t."""
        k = int(np.searchsorted(times, t))
        return int(firsts[k]) if k < firsts.size else data.shape[0]

    def time_of(i: int) -> float:
        k = int(np.searchsorted(firsts, i, side="right")) - 1
        return float(times[k] + (i - firsts[k]) / rate)

    onsets, dones = [], []
    rejected = {"outside capture": 0, "channel 2 not silent before": 0, "no change seen": 0}
    before = int(0.1 * rate)
    for there, back in sends:
        first, last = index_at(there), index_at(back)
        if first < before or last >= data.shape[0]:
            rejected["outside capture"] += 1
            continue
        if np.any(np.abs(data[first - before : first, 1]) > SILENT):
            rejected["channel 2 not silent before"] += 1  # not a clean trial
            continue
        after2 = np.flatnonzero(np.abs(data[first:last, 1]) > SILENT)
        after1 = np.flatnonzero(np.abs(data[first:last, 0]) > SILENT)
        if after2.size and after1.size and after1[-1] < last - first - 1:
            onsets.append(time_of(first + int(after2[0])) - there)
            dones.append(time_of(first + int(after1[-1]) + 1) - there)
        else:
            rejected["no change seen"] += 1
    if any(rejected.values()):
        print(f"latency trials left out: {rejected}", file=sys.stderr)
    return onsets, dones, rejected


def latency(trials: int, glide_ms: float) -> dict:
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    with tempfile.TemporaryDirectory() as tmp:
        extra = LINE + f"sources:\n  glide_ms: {glide_ms}\n"
        proc, port = start_serve(Path(tmp), output="sounddevice", extra_config=extra, env=env)
        try:
            time.sleep(1.0)
            load_before = os.getloadavg()[0]
            onsets, dones, rejected = latency_trials(port, trials)
        finally:
            stop_serve(proc)

    def stats(values: list[float]) -> dict:
        ms = [1e3 * v for v in values]
        return {
            "median_ms": statistics.median(ms) if ms else None,
            "p95_ms": float(np.percentile(ms, 95)) if ms else None,
            "max_ms": max(ms) if ms else None,
        }

    return {
        "glide_ms": glide_ms,
        "trials": len(onsets),
        "left_out": rejected,
        "load_avg_1min": load_before,
        "onset": stats(onsets),
        "done": stats(dones),
    }


def grid(n: int) -> dict[int, ChannelPosition]:
    side = int(np.ceil(np.sqrt(n)))
    return {k + 1: ChannelPosition(x=0.05 * (k % side), y=0.05 * (k // side)) for k in range(n)}


def mix_cost(rng: np.random.Generator) -> list[dict]:
    """Microseconds per mix (median of 200) for n sources on three layouts and every roll-off."""
    layouts = {
        "glove (6)": Layout(load_layout("glove").channels, "glove"),
        "vest-back (16)": Layout(load_layout("vest-back").channels, "vest-back"),
        "grid (64)": Layout(grid(64)),
    }
    out = []
    for name, layout in layouts.items():
        ctl = make_controller(channels=max(layout.channels) + 1)
        mixer = build_mixer(load_config(env={}, user_file=False), ctl, layout)
        coords = np.asarray(layout.coordinates)
        for law in ("smooth", "phantom"):
            for n in (1, 4, 16):
                views = [
                    SourceView(
                        index=i,
                        on=True,
                        position=tuple(coords[rng.integers(len(coords))] + rng.normal(0, 0.01, 3)),
                        target=(0.0, 0.0, 0.0),
                        radius=0.08,
                        rolloff=law,
                        intensity=float(rng.uniform(0.2, 1)),
                        balance=float(rng.uniform(-2, 2)),
                        preset=None,
                        speed=False,
                        speed_mm_s=0.0,
                        moving=True,
                    )
                    for i in range(n)
                ]
                times = []
                for _ in range(200):
                    t0 = time.perf_counter()
                    mixer.targets(views)
                    times.append(time.perf_counter() - t0)
                out.append({"layout": name, "rolloff": law, "sources": n, "mix_us": 1e6 * statistics.median(times)})
    return out


def flood_rate() -> dict:
    """OSC position messages handled per second with a running mixer (16 sources, vest layout)."""
    ctl = make_controller(channels=16)
    mixer = build_mixer(load_config(env={}, user_file=False), ctl, Layout(load_layout("vest-back").channels))
    handler = OscHandler(ctl, sync_worker=None)
    peer = FakePeer()
    mixer.start()
    try:
        handler.handle_batch([(encode_message(f"/vibsynth/source/{k}/on", (1,)), peer) for k in range(1, 17)])
        packets = [
            (encode_message(f"/vibsynth/source/{1 + k % 16}/pos", (0.001 * (k % 200) - 0.1, 0.0, 0.05)), peer)
            for k in range(50_000)
        ]
        mixes = mixer.mixes
        t0 = time.perf_counter()
        for start in range(0, len(packets), 100):  # batches as the receive loop hands them over
            handler.handle_batch(packets[start : start + 100])
        elapsed = time.perf_counter() - t0
        mixes = mixer.mixes - mixes
    finally:
        mixer.stop()
    return {"messages": len(packets), "seconds": elapsed, "per_second": len(packets) / elapsed, "mixes": mixes}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=40)
    parser.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "spatial.json")
    args = parser.parse_args()
    rng = np.random.default_rng(15)

    result: dict = {"latency": None}
    if jack_available():
        result["latency"] = [latency(args.trials, glide) for glide in (20.0, 0.0)]
    else:
        print("no JACK server (run under scripts/with_jack.sh): latency not measured", file=sys.stderr)
    result["mix"] = mix_cost(rng)
    result["flood"] = flood_rate()
    result["machine"] = {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()}
    result["when"] = time.strftime("%Y-%m-%d %H:%M:%S")

    if result["latency"]:
        print("OSC pos -> audible change (JACK dummy 48 kHz / 128, ms)")
        print(f"{'glide_ms':>8} {'trials':>6} {'onset med':>9} {'onset p95':>9} {'done med':>9} {'done p95':>9}")
        for r in result["latency"]:
            o, d = r["onset"], r["done"]
            print(
                f"{r['glide_ms']:>8g} {r['trials']:>6} {o['median_ms']:>9.2f} {o['p95_ms']:>9.2f} "
                f"{d['median_ms']:>9.2f} {d['p95_ms']:>9.2f}"
            )
    print("\nmix cost (us per mix, median)")
    print(f"{'layout':>15} {'rolloff':>8} {'sources':>7} {'us':>8}")
    for r in result["mix"]:
        print(f"{r['layout']:>15} {r['rolloff']:>8} {r['sources']:>7} {r['mix_us']:>8.0f}")
    f = result["flood"]
    print(
        f"\npos flood: {f['messages']} messages in {f['seconds']:.2f} s ({f['per_second']:.0f}/s), {f['mixes']} mixes"
    )
    atomic_write_text(args.json, json.dumps(result, indent=2))  # the folder is part of the repository
    print(f"\nJSON written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
