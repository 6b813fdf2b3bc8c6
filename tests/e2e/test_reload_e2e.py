"""End to end: preset hot reload stays off the audio path (issue 12, fault 5).

``vibsynth serve`` runs on the JACK dummy server with a user preset folder. Underflows are
counted from ``/status`` over OSC in two windows of the same run: a quiet baseline, then with
a 50 MB junk ``.yaml`` in the folder. The junk file is never read (the watcher looks at its size
only: tests/settings/test_presets.py), so the log says exactly once that it is skipped, the
audio does not collapse (before the fix the watcher re-read and hashed it every poll: about 3
underflows a second; the figures beside the machine's own noise are benchmarks/bench_rt_share.py's),
and hot reload keeps working beside it (a preset added afterwards is playable).

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_reload_e2e.py -q -s``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.jackutil import REALTIME, assert_no_collapse, e2e_required, jack_server_available
from tests.e2e.oscclient import OscClient as Osc
from tests.e2e.oscclient import free_udp_port
from tests.serveutil import stop_serve

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[2]
WINDOW_S = float(os.environ.get("VIBSYNTH_RELOAD_WINDOW_S", "5"))
JUNK_BYTES = 50 * 1024 * 1024
START_TIMEOUT_S = 180.0


def _start(tmp_path: Path, presets: Path) -> tuple[subprocess.Popen, int, Path]:
    port = free_udp_port()
    config = tmp_path / "vibsynth.yaml"
    config.write_text(f"version: 1\nosc:\n  port: {port}\n", encoding="utf-8")
    log_path = tmp_path / "serve.log"
    env = dict(
        os.environ,
        PYTHONPATH=str(ROOT),
        VIBSYNTH_HOST_API="JACK",
        JACK_NO_AUDIO_RESERVATION="1",
        VIBSYNTH_PRESETS_DIR=str(presets),
        XDG_CONFIG_HOME=str(tmp_path / "xdg-config"),
    )
    cmd = [
        sys.executable,
        "-m",
        "vibsynth",
        "serve",
        "--config",
        str(config),
        "--output",
        "sounddevice",
        "--no-midi",
        "--osc-port",
        str(port),
        "--intensity",
        "0.5",
    ]
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + START_TIMEOUT_S
    probe = Osc(port)
    try:
        while True:
            if proc.poll() is not None:
                raise AssertionError(f"serve exited ({proc.returncode}):\n{log_path.read_text()}")
            if time.monotonic() > deadline:
                stop_serve(proc)
                raise AssertionError("serve did not answer /ping in time:\n" + log_path.read_text())
            try:
                probe.request("/vibsynth/ping", 1, expect="/vibsynth/pong", timeout=0.5)
                return proc, port, log_path
            except (TimeoutError, ConnectionRefusedError):
                continue
    finally:
        probe.close()


def _underflows_over(client: Osc, seconds: float) -> int:
    """Underflows over ``seconds`` of streaming, with a knob move a second as a player would."""
    rng = np.random.default_rng(12)
    before = client.status()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        client.send("/vibsynth/balance", float(rng.uniform(-1.0, 1.0)))
        time.sleep(1.0)
    after = client.status()
    return int(after["underflows"] - before["underflows"])


@REALTIME
def test_a_50mb_file_in_the_preset_folder_is_skipped_once_and_reload_goes_on(tmp_path):
    ok, reason = jack_server_available()
    if not ok:
        if e2e_required():
            pytest.fail(f"VIBSYNTH_E2E_REQUIRED=1 but {reason}")
        pytest.skip(reason)
    presets = tmp_path / "presets"
    presets.mkdir()
    (presets / "mine.yaml").write_text("version: 1\nintensity: 0.4\nbalance: 0.2\n", encoding="utf-8")
    proc, port, log_path = _start(tmp_path, presets)
    client = Osc(port)
    try:
        time.sleep(1.0)  # stream start-up is not the steady state
        baseline = _underflows_over(client, WINDOW_S)

        # 50 MB of (seeded) junk, written under a hidden name and renamed in: the watcher
        # sees the whole file at once, as it would after a copy.
        junk = presets / "junk.yaml"
        hidden = presets / ".junk.yaml.part"
        block = np.random.default_rng(5).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
        with open(hidden, "wb") as fh:
            for _ in range(JUNK_BYTES // len(block)):
                fh.write(block)
        os.replace(hidden, junk)
        time.sleep(1.5)  # the watcher (0.5 s polls) has seen it
        loaded = _underflows_over(client, WINDOW_S)

        # hot reload still works beside the junk file
        (presets / "added.yaml").write_text("version: 1\nintensity: 0.6\nbalance: -0.3\n", encoding="utf-8")
        deadline = time.monotonic() + 5.0
        while True:
            client.send("/vibsynth/preset", "added")
            if client.request("/vibsynth/get", "preset", expect="/vibsynth/preset").args == ("added",):
                break
            assert time.monotonic() < deadline, "a preset added next to the junk file was not picked up"
            time.sleep(0.2)
    finally:
        client.close()
        stop_serve(proc)
    log = log_path.read_text()
    print(f"\nunderflows per {WINDOW_S:g} s: baseline {baseline}, with a 50 MB file in the preset folder {loaded}")
    skipped = [line for line in log.splitlines() if "junk.yaml" in line]
    assert len(skipped) == 1, log
    assert "over the 1 MiB limit" in skipped[0] and "not read" in skipped[0], skipped[0]
    assert "Traceback" not in log
    assert_no_collapse(loaded, WINDOW_S, "a 50 MB file in the preset folder")
