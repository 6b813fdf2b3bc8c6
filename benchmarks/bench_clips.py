"""Benchmark of the clip files: loading, library reload, AHAP / .haptic import, AHAP export, and the
refusal of hostile files (how long one clear error takes).

Everything here runs on control threads (the CLI, the studio's workers, the watcher), never in the
audio callback; the numbers say how long a designer or a hot reload waits. Prints a table and
writes ``benchmarks/results/bench_clips.json``.

Run: ``python benchmarks/bench_clips.py [--quick]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.errors import ClipError  # noqa: E402
from vibsynth.formats.ahap import ahap_text, parse_ahap, read_ahap  # noqa: E402
from vibsynth.formats.meta_haptic import parse_meta_haptic  # noqa: E402
from vibsynth.settings.clip_convert import ClipMapping, clip_from_design, design_from_clip  # noqa: E402
from vibsynth.settings.clips import (  # noqa: E402
    Clip,
    ClipLibrary,
    Keyframe,
    Transient,
    clip_to_yaml,
    load_clip,
    save_clip,
    shipped_clips_dir,
)
from vibsynth.settings.models_clip import MAX_KEYFRAMES  # noqa: E402


def timed(func: Callable[[], object], repeat: int) -> float:
    """Median wall time of ``func`` in milliseconds."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        func()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1000.0)


def big_clip(n: int, rng: np.random.Generator) -> Clip:
    t = np.cumsum(rng.uniform(1, 20, n))
    keys = tuple(
        Keyframe(
            float(round(ti, 3)),
            float(round(rng.uniform(0, 1), 4)),
            float(round(rng.uniform(-3, 3), 4)),
            str(rng.choice(["linear", "hold", "smooth"])),
        )
        for ti in t
    )
    taps = tuple(Transient(float(round(ti, 3)), 0.8, 1.0, 30.0) for ti in t[:: max(1, n // 200)])
    return Clip("big", float(t[-1]), keys, taps)


def ahap_pattern(n_events: int, rng: np.random.Generator) -> str:
    pattern, t = [], 0.0
    for k in range(n_events):
        t += float(rng.uniform(0.005, 0.05))
        params = [
            {"ParameterID": "HapticIntensity", "ParameterValue": round(float(rng.uniform(0, 1)), 3)},
            {"ParameterID": "HapticSharpness", "ParameterValue": round(float(rng.uniform(0, 1)), 3)},
        ]
        if k % 3:
            pattern.append({"Event": {"Time": round(t, 4), "EventType": "HapticTransient", "EventParameters": params}})
        else:
            d = float(rng.uniform(0.01, 0.05))
            pattern.append(
                {
                    "Event": {
                        "Time": round(t, 4),
                        "EventType": "HapticContinuous",
                        "EventDuration": round(d, 4),
                        "EventParameters": params,
                    }
                }
            )
            t += d
    return json.dumps({"Version": 1, "Pattern": pattern})


def meta_envelope(n: int, rng: np.random.Generator) -> str:
    times = np.round(np.cumsum(rng.uniform(0.001, 0.01, n)), 5)
    amplitude = [{"time": float(t), "amplitude": round(float(a), 3)} for t, a in zip(times, rng.uniform(0, 1, n))]
    frequency = [{"time": float(t), "frequency": round(float(f), 3)} for t, f in zip(times[::4], rng.uniform(0, 1, n))]
    return json.dumps(
        {
            "version": {"major": 1},
            "signals": {"continuous": {"envelopes": {"amplitude": amplitude, "frequency": frequency}}},
        }
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and smaller files")
    args = parser.parse_args(argv)
    repeat = 3 if args.quick else 7
    rng = np.random.default_rng(16)
    mapping = ClipMapping()
    rows: list[dict[str, object]] = []

    def row(case: str, ms: float, note: str = "") -> None:
        rows.append({"case": case, "ms": round(ms, 3), "note": note})

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        heart = shipped_clips_dir() / "heartbeat.yaml"
        row("load a shipped clip (heartbeat)", timed(lambda: load_clip(heart), repeat * 5))
        big = big_clip(MAX_KEYFRAMES, rng)
        big_path = save_clip(big, folder / "big.yaml")
        row(
            f"load a clip of {MAX_KEYFRAMES} keyframes",
            timed(lambda: load_clip(big_path), repeat),
            f"{big_path.stat().st_size / 1024:.0f} KiB",
        )
        times = np.linspace(0, big.duration_ms, 48_000)
        row("evaluate 48,000 points of that clip (values_at)", timed(lambda: big.values_at(times), repeat))

        user = folder / "user"
        user.mkdir()
        n_files = 200 if args.quick else 1000
        for i in range(n_files):
            (user / f"c{i:04d}.yaml").write_text(clip_to_yaml(Clip(f"c{i:04d}", 100.0, (Keyframe(0, 0.5, 0.0),))))
        lib = ClipLibrary(None, user, load=False)
        row(f"library: first read of {n_files} files", timed(lambda: ClipLibrary(None, user), 1))
        lib.reload()
        lib._clock = lambda: time.time_ns() + 10 * 10**9  # past the racy window: a steady-state poll
        lib.reload()
        row(f"library: a hot-reload poll, {n_files} unchanged files (stat only)", timed(lib.reload, repeat))

        for n in (100, 1000) if args.quick else (100, 1000, 3000):
            text = ahap_pattern(n, rng)
            design = parse_ahap(text, "x.ahap")
            row(
                f"AHAP import: parse {n} events",
                timed(lambda: parse_ahap(text, "x.ahap"), repeat),
                f"{len(text) / 1024:.0f} KiB",
            )
            row(f"AHAP import: map {n} events to a clip", timed(lambda: clip_from_design(design, "x", mapping), repeat))
        text = meta_envelope(2000, rng)
        row(
            "Meta import: 2000 amplitude breakpoints + emphasis-free envelope",
            timed(lambda: clip_from_design(parse_meta_haptic(text, "x.haptic"), "x", mapping), repeat),
        )
        shipped = ClipLibrary(shipped_clips_dir(), None).get("rain")
        row(
            "AHAP export of rain (4 smooth keyframes, 52 transients)",
            timed(lambda: ahap_text(design_from_clip(shipped, mapping)), repeat),
        )

        hostile = {
            "truncated JSON": '{"Version": 1, "Pattern": [{"Event": {"Time": 0.0, "EventType": "Hap',
            "NaN time": '{"Pattern": [{"Event": {"Time": NaN, "EventType": "HapticTransient"}}]}',
            "100,000-deep nesting": "[" * 100_000 + "]" * 100_000,
            "20,000 events (over the count cap)": json.dumps(
                {"Pattern": [{"Event": {"Time": 0, "EventType": "HapticTransient"}}] * 20_000}
            ),
        }
        for case, text in hostile.items():

            def refuse(text: str = text) -> None:
                try:
                    parse_ahap(text, "x.ahap")
                except ClipError:
                    return
                raise AssertionError("accepted")

            row(f"refuse: {case}", timed(refuse, repeat))
        huge = folder / "huge.ahap"
        huge.write_bytes(b"[" + b"0," * (25 << 20) + b"0]")

        def refuse_file() -> None:
            try:
                read_ahap(huge)
            except ClipError:
                return

        row("refuse: a 50 MB file (size checked before reading)", timed(refuse_file, repeat))

    width = max(len(str(r["case"])) for r in rows)
    print(f"{'case':<{width}}  {'ms':>9}  note")
    for r in rows:
        print(f"{r['case']!s:<{width}}  {r['ms']:>9.3f}  {r['note']}")
    out = ROOT / "benchmarks" / "results" / "bench_clips.json"
    out.write_text(json.dumps({"quick": args.quick, "rows": rows}, indent=2) + "\n")
    print(f"\nwrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
