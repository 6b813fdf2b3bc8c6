"""Benchmark of the perception lab: preparing sessions, recording trials, and how exactly pairs play.

* preparation: the stimulus set loaded and prepared, the plan drawn and the session folder
  written, per protocol, for the 18 shipped presets at 48 kHz and 1 s stimuli (the paper's
  size) and for 6 engine renders;
* recording: one trial's row appended and fsynced (171 dissimilarity trials);
* the runner on a real engine rendered offline (48 kHz): time of an answer (the row written,
  the next pair scheduled), and the onset error of each stimulus of a pair, found by
  matching the rendered output against the stimulus (0 samples = sample-exact).

Prints a table and writes ``benchmarks/results/bench_lab.json``.

Run: ``python benchmarks/bench_lab.py [--quick]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.app.lab.runner import LEAD_S, LabRunner  # noqa: E402
from vibsynth.control.controller import Controller  # noqa: E402
from vibsynth.engine.bank import BankSpec, build_bank  # noqa: E402
from vibsynth.engine.engine import Engine  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402
from vibsynth.research.lab.build import SessionRequest, new_session  # noqa: E402
from vibsynth.research.lab.protocol import PROTOCOLS, LabParameters  # noqa: E402
from vibsynth.research.lab.records import Answer  # noqa: E402
from vibsynth.research.lab.stimuli import load_set  # noqa: E402
from vibsynth.settings.library import PresetLibrary, shipped_presets_dir  # noqa: E402

FS = 48000.0


def prepare_times(root: Path, spec: str, basis, presets) -> dict[str, float]:
    out = {}
    for protocol in PROTOCOLS:
        t0 = time.perf_counter()
        stimuli = load_set(spec, presets=presets, fs=FS, seconds=1.0, seed=1, basis=basis)
        session = new_session(root, SessionRequest(protocol, "bench", 1), stimuli, basis=basis)
        out[protocol] = time.perf_counter() - t0
        session.close()
    return out


def record_times(root: Path, basis, presets) -> list[float]:
    stimuli = load_set("presets", presets=presets, fs=FS, seconds=1.0, seed=1, basis=basis)
    now = datetime.now(timezone.utc)
    times = []
    with new_session(root, SessionRequest("dissimilarity", "rec", 2), stimuli, basis=basis) as s:
        while s.next_trial is not None:
            t0 = time.perf_counter()
            s.record(Answer(value=0.5), shown_at=now, answered_at=now)
            times.append(time.perf_counter() - t0)
    return times


def onset(out: np.ndarray, samples: np.ndarray, guess: int, search: int = 200) -> int:
    """Where ``samples`` (inside its 5 ms fades) best matches ``out`` near ``guess``, minus ``guess``."""
    fade = int(0.005 * FS)
    core = samples[fade:-fade]
    errors = [
        np.sum((out[guess + d + fade : guess + d + fade + core.size] - core) ** 2) for d in range(-search, search + 1)
    ]
    return int(np.argmin(errors)) - search


def runner_times(root: Path, basis, pairs: int) -> dict[str, list[float]]:
    bank = build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, balance_min=-3.5, balance_max=3.5, levels=9, seed=1))
    engine = Engine(bank, channels=1, glide_s=0.0, initial_intensity=0.0)
    controller = Controller(engine)
    stimuli = load_set("renders:6", presets=lambda: [], fs=FS, seconds=1.0, seed=3, basis=basis)
    session = new_session(
        root, SessionRequest("dissimilarity", "run", 3, LabParameters(familiarisation_pairs=0)), stimuli, basis=basis
    )
    runner = LabRunner(engine, controller)
    runner.start(session)
    sounds = {k: v.samples.astype(np.float32).astype(np.float64) for k, v in session.stimuli().items()}
    lead, n, gap = int(LEAD_S * FS), int(FS), int(0.5 * FS)
    answers, errors = [], []
    for k in range(min(pairs, session.total)):
        a, b = session.plan.test[k].stimuli
        out = engine.render(lead + 2 * n + gap + 1000)[:, 0].astype(np.float64)
        errors += [onset(out, sounds[a], lead), onset(out, sounds[b], lead + n + gap)]
        t0 = time.perf_counter()
        runner.answer(value=0.5)
        answers.append(time.perf_counter() - t0)
    runner.close()
    return {"answer_s": answers, "onset_error_samples": errors}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer pairs on the engine")
    args = parser.parse_args()
    basis = default_basis()
    presets = PresetLibrary(shipped_presets_dir(), None).presets
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        prepare_times(root / "w", "renders:3", basis, presets)  # warm-up: imports, caches (not reported)
        prep_presets = prepare_times(root / "p", "presets", basis, presets)
        prep_renders = prepare_times(root / "r", "renders:6", basis, presets)
        records = record_times(root / "c", basis, presets)
        run = runner_times(root / "e", basis, 5 if args.quick else 21)
    ms = lambda v: 1000 * float(v)  # noqa: E731
    rows = [(f"prepare, 18 presets, {p}", f"{prep_presets[p]:.1f} s") for p in PROTOCOLS]
    rows += [(f"prepare, 6 renders, {p}", f"{prep_renders[p]:.1f} s") for p in PROTOCOLS]
    record_ms = (ms(np.median(records)), ms(np.percentile(records, 95)))
    answer_ms = (ms(np.median(run["answer_s"])), ms(np.percentile(run["answer_s"], 95)))
    worst = max(abs(e) for e in run["onset_error_samples"])
    rows += [
        ("record a trial (append + fsync), median / p95", f"{record_ms[0]:.2f} / {record_ms[1]:.2f} ms"),
        ("answer -> next pair scheduled, median / p95", f"{answer_ms[0]:.2f} / {answer_ms[1]:.2f} ms"),
        ("pair onset error (samples), max |e|", f"{worst} over {len(run['onset_error_samples'])} onsets"),
    ]
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    results = {
        "rate_hz": FS,
        "prepare_presets_s": prep_presets,
        "prepare_renders_s": prep_renders,
        "record_ms": {"median": ms(np.median(records)), "p95": ms(np.percentile(records, 95)), "n": len(records)},
        "answer_ms": {"median": ms(np.median(run["answer_s"])), "p95": ms(np.percentile(run["answer_s"], 95))},
        "onset_error_samples": run["onset_error_samples"],
    }
    out = ROOT / "benchmarks" / "results" / "bench_lab.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
