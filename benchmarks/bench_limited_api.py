"""What the limited API (abi3) costs the real-time paths (issue 32): the same sources built twice.

    python benchmarks/bench_limited_api.py [--rounds 5] [--blocks 4000] [--datagrams 100000]
    python benchmarks/bench_limited_api.py --rev 4496c47    # also the sources of that commit

Builds the three extensions into temporary copies of the package: ``limited`` (as the wheels
are: ``Py_LIMITED_API`` 0x030B0000, setup.py's default) and ``full`` (``VIBSYNTH_LIMITED_API=0``:
the whole C API, a version-specific build), plus, with ``--rev``, the sources of an older
commit built as they were. Each round runs every variant once, in turn, in its own process:

* **render**: ``Engine.render_into`` of a 128-frame block at 48 kHz, 1 and 8 channels, a new
  knob target every 10 blocks (the glide path), 50 warm-up blocks; the block's thread CPU time
  (``CLOCK_THREAD_CPUTIME_ID``: the time other jobs of a shared machine take is not counted) and
  its wall time, median over the blocks;
* **fast path**: the OSC receive loop (``_fast.Receiver`` on a UDP socket on 127.0.0.1, the
  engine's core behind it) taking ``/vibsynth/intensity f`` and ``/vibsynth/ch/0/balance f``
  datagrams sent in bursts of 32, the engine rendering two blocks after each burst (it drains
  the command ring); the receive thread's CPU time divided by the datagrams the fast path took.

Prints a table of the medians over the rounds and writes
benchmarks/results/limited_api-<timestamp>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FS = 48000
FRAMES = 128

# Runs inside a variant's copy (its folder first on sys.path); prints one JSON line.
CHILD = r"""
import json, socket, struct, sys, threading, time
import numpy as np
from vibsynth.control.osc import _fast
from vibsynth.engine import _core
from vibsynth.engine.bank import BankSpec, load_or_build
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis

blocks, datagrams, cache = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
bank, _ = load_or_build(default_basis(), BankSpec(fs=48000), cache_dir=cache)
result = {"core": _core.__file__.rsplit("/", 1)[-1], "fast": _fast.__file__.rsplit("/", 1)[-1]}

for channels in (1, 8):
    engine = Engine(bank, channels=channels, initial_intensity=0.5, max_block=128)
    out = np.zeros((128, channels), dtype=np.float32)
    rng = np.random.default_rng(1)
    for _ in range(50):
        engine.render_into(out)
    cpu, wall = np.empty(blocks), np.empty(blocks)
    for n in range(blocks):
        if n % 10 == 0:
            engine.submit(SetKnob("balance", float(rng.uniform(-3, 3))))
            engine.submit(SetKnob("intensity", float(rng.uniform(0.1, 1))))
        w, c = time.perf_counter_ns(), time.thread_time_ns()
        engine.render_into(out)
        cpu[n], wall[n] = time.thread_time_ns() - c, time.perf_counter_ns() - w
    result[f"render_{channels}ch_cpu_us"] = float(np.median(cpu)) / 1e3
    result[f"render_{channels}ch_wall_us"] = float(np.median(wall)) / 1e3


def osc(address, value):
    pad = lambda b: b + b"\0" * (4 - len(b) % 4)
    return pad(address.encode()) + pad(b",f") + struct.pack(">f", value)


engine = Engine(bank, channels=2, initial_intensity=0.5, max_block=128)
out = np.zeros((128, 2), dtype=np.float32)
rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
rx.bind(("127.0.0.1", 0))
rx.setblocking(False)
table = [(b"/vibsynth/intensity", _fast.M_INTENSITY, -1), (b"/vibsynth/ch/0/balance", _fast.M_BALANCE, 0)]
receiver = _fast.Receiver(rx.fileno(), engine._core, table, -3.0, 3.0, lambda batch: None, lambda *state: None, None)
thread = threading.Thread(target=receiver.run)
thread.start()
clock = time.pthread_getcpuclockid(thread.ident)
tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
rng = np.random.default_rng(2)
messages = [osc("/vibsynth/intensity", float(v)) for v in rng.uniform(0.1, 1.0, 509)]
messages += [osc("/vibsynth/ch/0/balance", float(v)) for v in rng.uniform(-2.0, 2.0, 503)]
rng.shuffle(messages)
address = rx.getsockname()
time.sleep(0.2)
before_cpu, before_fast = time.clock_gettime_ns(clock), receiver.counters()["fast"]
sent = 0
while sent < datagrams:
    for k in range(32):
        tx.sendto(messages[(sent + k) % len(messages)], address)
    sent += 32
    engine.render_into(out)
    engine.render_into(out)
deadline = time.monotonic() + 5
while receiver.counters()["packets"] < sent and time.monotonic() < deadline:
    engine.render_into(out)
    time.sleep(0.001)
cpu_ns, counters = time.clock_gettime_ns(clock) - before_cpu, receiver.counters()
receiver.stop()
thread.join()
taken = counters["fast"] - before_fast
result["fast_path_cpu_ns_per_datagram"] = cpu_ns / max(taken, 1)
result["fast_path_taken"] = taken
result["fast_path_sent"] = sent
result["fast_path_ring_full"] = counters["ring_full"]
print(json.dumps(result))
"""


def make_variant(base: Path, name: str, *, limited: bool, rev: str | None = None) -> Path:
    """A copy of the package (of the working tree, or of commit ``rev``) with its extensions built in place."""
    folder = base / name
    folder.mkdir()
    if rev is None:
        for item in ("setup.py", "pyproject.toml", "vibsynth"):
            source = ROOT / item
            if source.is_dir():
                shutil.copytree(source, folder / item, ignore=shutil.ignore_patterns("*.so", "*.pyd", "__pycache__"))
            else:
                shutil.copy2(source, folder / item)
    else:
        archive = subprocess.run(
            ["git", "archive", rev, "setup.py", "pyproject.toml", "vibsynth"], cwd=ROOT, capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    env = {**os.environ, "VIBSYNTH_LIMITED_API": "1" if limited else "0"}
    subprocess.run(
        [sys.executable, "setup.py", "-q", "build_ext", "--inplace"],
        cwd=folder,
        env=env,
        check=True,
        capture_output=True,
        timeout=600,
    )
    return folder


def run_variant(folder: Path, blocks: int, datagrams: int, cache: str) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(blocks), str(datagrams), cache],
        cwd=folder,
        env={**os.environ, "PYTHONPATH": str(folder)},
        capture_output=True,
        text=True,
        timeout=900,
    )
    if done.returncode != 0:
        raise SystemExit(f"{folder.name}: {done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--blocks", type=int, default=4000, help="blocks rendered per channel count and round")
    parser.add_argument("--datagrams", type=int, default=100_000, help="datagrams sent per round")
    parser.add_argument("--rev", help="also build the sources of this commit (the whole C API, as they were)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="vibsynth-abi-") as tmp:
        base = Path(tmp)
        cache = str(base / "bank-cache")
        variants = {
            "limited": make_variant(base, "limited", limited=True),
            "full": make_variant(base, "full", limited=False),
        }
        if args.rev:
            variants[f"rev {args.rev}"] = make_variant(base, "rev", limited=False, rev=args.rev)
        runs: dict[str, list[dict]] = {name: [] for name in variants}
        for r in range(args.rounds):
            for name, folder in variants.items():
                runs[name].append(run_variant(folder, args.blocks, args.datagrams, cache))
            print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)

    keys = [k for k in runs["limited"][0] if isinstance(runs["limited"][0][k], float)]
    summary = {name: {k: float(np.median([run[k] for run in rs])) for k in keys} for name, rs in runs.items()}
    print(f"{'median over ' + str(args.rounds) + ' rounds':36s}" + "".join(f"{n:>16s}" for n in variants))
    for k in keys:
        print(f"{k:36s}" + "".join(f"{summary[n][k]:16.3f}" for n in variants))
    for name, rs in runs.items():
        print(
            f"{name}: {rs[0]['core']}, {rs[0]['fast']}; fast path took {rs[-1]['fast_path_taken']} of "
            f"{rs[-1]['fast_path_sent']} (ring full {rs[-1]['fast_path_ring_full']})"
        )
    path = args.json or ROOT / "benchmarks" / "results" / f"limited_api-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"rounds": args.rounds, "summary": summary, "runs": runs}, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
