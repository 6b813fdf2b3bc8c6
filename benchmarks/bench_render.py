"""Offline rendering to WAV: peak memory and wall time of the one renderer, per kind and length.

Each case runs the command line in its own child process, which reports its peak RSS
(``resource.getrusage(RUSAGE_SELF).ru_maxrss``), the wall time of ``main()`` (bank
loaded from a warm cache; imports excluded) and its CPU time (user + system, imports
included). Kinds, all at 48 kHz, mono float32:

* ``texture``  ``vibsynth render --balance 0.3 --intensity 0.8`` (closed-form synthesis, one period repeated)
* ``midi``     ``vibsynth render --midi`` of a generated file: notes and a CC 74 move every 50 ms
* ``preset``   ``vibsynth preset play brick -o`` (the engine with one preset)
* ``decode``   ``vibsynth decode --rate 48000`` of a generated per-window ``.vbt`` (a knob move every 50 ms)
* ``serve``    ``vibsynth serve --output wav -o`` (``WavOutput``: the engine rendered as fast as possible)

Lengths: 60 s and 600 s; ``--long`` adds 3600 s. Prints a table and writes
``benchmarks/results/bench_render.json``.

Run: ``python benchmarks/bench_render.py [--long] [--kinds texture,midi] [--seconds 60,600]``.
``--code DIR`` measures another copy of the package (e.g. the code before the one renderer:
``git archive <rev> vibsynth | tar -x -C DIR`` plus the compiled ``.so`` files) with ``--label``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "benchmarks" / "results" / "bench_render.json"
KINDS = ("texture", "midi", "preset", "decode", "serve")
RATE = 48000

CHILD = textwrap.dedent(
    """
    import json, resource, sys, time
    from vibsynth.cli import main
    started = time.perf_counter()
    try:
        code = main(sys.argv[1:])
        error = None
    except BaseException as exc:  # an old loop may fail (e.g. a full schedule): record it
        code, error = -1, f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - started
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"code": code, "error": error, "wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
                      "peak_rss_mb": usage.ru_maxrss / 1024}))
    """
)


def write_midi(path: Path, seconds: float) -> None:
    """A note held over the whole file, CC 74 stepping every 50 ms, CC 11 every second."""
    import mido

    tpb, per_s = 480, 960  # 120 bpm: 960 ticks per second
    mid = mido.MidiFile(ticks_per_beat=tpb)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.MetaMessage("set_tempo", tempo=500000, time=0))
    track.append(mido.Message("note_on", note=60, velocity=110, time=0))
    steps = int(seconds / 0.05)
    for i in range(steps):
        track.append(mido.Message("control_change", control=74, value=int(64 + 63 * np.sin(i / 40)), time=48))
        if i % 20 == 0:
            track.append(mido.Message("control_change", control=11, value=int(90 + 37 * np.cos(i / 200)), time=0))
    track.append(mido.Message("note_off", note=60, time=int(0.05 * per_s)))
    mid.save(path)


def write_vbt(path: Path, seconds: float) -> None:
    """A per-window trajectory (a knob move every 50 ms) at 2.8 kHz, levels and t1 wandering."""
    from vibsynth.dsp.codec import Quantizer, Trajectory
    from vibsynth.formats import vbt
    from vibsynth.formats.basis_file import default_basis

    fs, window, hop = 2800.0, 280, 140
    n = int(seconds * fs)
    frames = (n - window) // hop + 1
    rng = np.random.default_rng(7)
    level = -40.0 + 8.0 * np.sin(np.arange(frames) / 300.0) + rng.normal(0, 0.5, frames)
    t1 = 15.0 * np.sin(np.arange(frames) / 170.0) + rng.normal(0, 0.5, frames)
    traj = Trajectory(fs, n, window, hop, level, t1, default_basis().id)
    vbt.write_vbt(path, traj, Quantizer.fit(traj))


def case_args(kind: str, seconds: float, work: Path, config: Path, out: Path) -> list[str]:
    s = f"{seconds:g}"
    if kind == "texture":
        return ["render", "--balance", "0.3", "--intensity", "0.8", "--seconds", s, "--seed", "1", "-o", str(out)]
    if kind == "midi":
        mid = work / f"perf-{s}.mid"
        if not mid.exists():
            write_midi(mid, seconds)
        return ["render", "--midi", str(mid), "--config", str(config), "--seconds", s, "-o", str(out)]
    if kind == "preset":
        return ["preset", "play", "brick", "--config", str(config), "--seconds", s, "-o", str(out)]
    if kind == "decode":
        traj = work / f"traj-{s}.vbt"
        if not traj.exists():
            write_vbt(traj, seconds)
        return ["decode", str(traj), "--rate", str(RATE), "--config", str(config), "-o", str(out)]
    if kind == "serve":
        flags = ["--output", "wav", "--intensity", "0.5", "--no-osc", "--no-midi"]
        return ["serve", "--config", str(config), *flags, "--seconds", s, "-o", str(out)]
    raise ValueError(kind)


def run_case(args: list[str], code_dir: Path | None, cwd: Path) -> dict[str, Any]:
    """Run ``vibsynth ARGS`` in a child process (in ``cwd``: with ``-c`` the current folder comes first
    on ``sys.path``, so it must not hold another copy of the package)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(code_dir)] * (code_dir is not None) + [str(ROOT)] + [env.get("PYTHONPATH", "")]
    ).rstrip(os.pathsep)
    done = subprocess.run(
        [sys.executable, "-c", CHILD, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=3 * 3600
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if not lines:
        return {"code": done.returncode, "error": (done.stderr.strip().splitlines() or ["killed"])[-1]}
    result = json.loads(lines[-1])
    if result["code"] != 0 and not result.get("error"):
        result["error"] = (done.stderr.strip().splitlines() or [""])[-1]
    return result


def measure(kind: str, seconds: float, args: list[str], out: Path, code_dir: Path | None, cwd: Path) -> dict[str, Any]:
    """One case: :func:`run_case`, labelled with its kind and length, the output's size noted and the output removed."""
    result = run_case(args, code_dir, cwd)
    result.update(kind=kind, seconds=seconds)
    if out.exists():
        result["file_mb"] = round(out.stat().st_size / 2**20, 1)
        out.unlink()
    return result


def write_config(work: Path) -> Path:
    """A config in ``work`` at :data:`RATE`, its bank cache in ``work/banks`` (warmed once, loaded by every case)."""
    config = work / "config.yaml"
    config.write_text(f"audio:\n  rate: {RATE}\nbank:\n  cache_dir: {work / 'banks'}\n")
    return config


def save_run(path: Path, label: str, run: dict[str, Any]) -> None:
    """Store ``run`` (with the machine and the date) as ``runs[label]`` of the JSON file; other labels are kept."""
    data: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    data.setdefault("runs", {})[label] = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M:%S"), **run}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")


def machine() -> dict[str, Any]:
    info: dict[str, Any] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
    }
    try:
        cpuinfo = Path("/proc/cpuinfo").read_text()
        info["cpu"] = next(line.split(":", 1)[1].strip() for line in cpuinfo.splitlines() if "model name" in line)
        mem = next(line for line in Path("/proc/meminfo").read_text().splitlines() if line.startswith("MemTotal"))
        info["mem_gb"] = round(int(mem.split()[1]) / 2**20, 1)
    except (OSError, StopIteration):
        pass
    try:
        info["commit"] = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
    except OSError:
        pass
    return info


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--long", action="store_true", help="also render 3600 s")
    parser.add_argument("--seconds", help="comma-separated lengths (default 60,600[,3600])")
    parser.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated subset of {','.join(KINDS)}")
    parser.add_argument("--code", type=Path, help="measure this copy of the package instead of the working tree")
    parser.add_argument("--label", default="one renderer", help="name of this run in the JSON")
    parser.add_argument("--json", type=Path, default=RESULTS, help="results file (runs with other labels are kept)")
    args = parser.parse_args()
    lengths = [float(s) for s in args.seconds.split(",")] if args.seconds else [60.0, 600.0] + [3600.0] * args.long
    kinds = [k for k in args.kinds.split(",") if k]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_render-") as tmp:
        work = Path(tmp)
        config = write_config(work)
        # warm the bank cache (48 kHz default grid) so that every case loads it
        run_case(
            ["preset", "play", "brick", "--config", str(config), "--seconds", "0.1", "-o", str(work / "w.wav")],
            args.code,
            work,
        )
        for seconds in lengths:
            for kind in kinds:
                out = work / f"{kind}-{seconds:g}.wav"
                result = measure(kind, seconds, case_args(kind, seconds, work, config, out), out, args.code, work)
                rows.append(result)
                status = f"ERROR {result['error']}" if result.get("code") else ""
                print(
                    f"{kind:8s} {seconds:7.0f} s  peak RSS {result.get('peak_rss_mb', float('nan')):8.1f} MB  "
                    f"wall {result.get('wall_s', float('nan')):7.2f} s  file {result.get('file_mb', 0):7.1f} MB "
                    f"{status}",
                    flush=True,
                )
    save_run(
        args.json,
        args.label,
        {
            "settings": f"{RATE} Hz, 1 channel, float32 WAV, default bank (49 levels x 4 s) from a warm cache",
            "code": str(args.code) if args.code else "working tree",
            "cases": rows,
        },
    )
    print(f"\n{'kind':8s} {'seconds':>8s} {'peak RSS MB':>12s} {'wall s':>8s} {'file MB':>8s}")
    for r in rows:
        rss = f"{r['peak_rss_mb']:.0f}" if "peak_rss_mb" in r else "-"
        wall = f"{r['wall_s']:.2f}" if "wall_s" in r else "-"
        note = f"  ({r['error']})" if r.get("code") else ""
        print(f"{r['kind']:8s} {r['seconds']:8.0f} {rss:>12s} {wall:>8s} {r.get('file_mb', 0):8.1f}{note}")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
