"""Per-channel actuator profiles on the JACK dummy server: one serve, three different actuators, one feel.

One ``vibsynth serve`` with three channels plays the same texture on each; each channel drives
its own simulated actuator (a JACK client in its own process, from
:mod:`tests.e2e.test_calibrate_e2e`: a 2nd-order resonance, a sensitivity, seeded noise),
which records what it does. The actuators differ by an octave in resonance and by +-6 dB in
sensitivity. Their profiles are their **true** responses written as absolute profiles
(measuring them with ``calibrate response --channels all`` is tested in test_calibrate_e2e.py,
and takes ~30 s more; its profiles are within 0.25 dB of these). With one profile for every
channel (the engine before per-channel trims) the actuators feel ~13 dB and ~0.75 balance
apart; with ``actuator.channel_profiles: sim-ch{n}`` the trims bring them together.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.e2e.test_calibrate_e2e import ACTUATORS, REPO, SimulatedActuator, env_of, resonance_sos, response_db

pytestmark = pytest.mark.e2e

FS = 48000.0
#: Intensity 0.8 is -48 dB at the default mapping: the 80-200 Hz level every actuator should reach.
KNOB_LEVEL_DB = -48.0


def write_true_profiles(tmp_path: Path) -> None:
    folder = tmp_path / "config" / "vibsynth" / "actuators"
    folder.mkdir(parents=True, exist_ok=True)
    freqs = np.geomspace(5.0, 2000.0, 300)
    for k, (f0, q, gain) in enumerate(ACTUATORS, start=1):
        db = response_db(resonance_sos(f0, q, gain, FS), freqs, FS)
        doc = {
            "name": f"sim-ch{k}",
            "description": f"simulated actuator: {f0:g} Hz, Q {q:g}, {gain:+g} dB (its true response)",
            "absolute": True,
            "rate": int(FS),
            "response": [[round(float(f), 3), round(float(d), 4)] for f, d in zip(freqs, db, strict=True)],
        }
        (folder / f"sim-ch{k}.yaml").write_text(yaml.safe_dump(doc))


def felt_by_each(tmp_path: Path, sims: list[SimulatedActuator], *settings: str) -> list[np.ndarray]:
    """What each actuator does over one bank loop (4 s) while one serve plays intensity 0.8, balance +1."""
    cmd = [
        sys.executable, "-m", "vibsynth", "serve", "--seconds", "60", "--no-osc", "--no-midi", "--no-studio",
        "--set", "audio.host_api=JACK", "--set", f"audio.channels={len(sims)}", "--set", "actuator.max_boost_db=45",
        "--set", "knobs.initial_intensity=0.8", "--set", "knobs.initial_balance=1.0",
        "--set", "discovery.enabled=false", *settings,
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, env=env_of(tmp_path), cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while not all(sim.patch.get_all_connections(f"{sim.name}:in") for sim in sims):
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                raise AssertionError(f"serve did not start: {proc.communicate()[0].decode()[-2000:]}")
            time.sleep(0.05)
        time.sleep(1.0)  # past the start's fade and the trims' glide
        frames = int(4.0 * FS)  # exactly one loop of the bank: the recording holds its whole spectrum
        for k, sim in enumerate(sims):  # all three record the same 4 s
            assert sim.proc.stdin is not None
            sim.proc.stdin.write(f"record {frames} {tmp_path / f'felt{k}.npy'}\n")
            sim.proc.stdin.flush()
        out = []
        for k, sim in enumerate(sims):
            assert sim.proc.stdout is not None
            answer = sim.proc.stdout.readline().split()
            assert answer[0] == "recorded", answer
            print(f"actuator {k + 1} missed {answer[1]} JACK cycles while recording")
            out.append(np.load(tmp_path / f"felt{k}.npy").astype(np.float64))
        return out
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def test_one_serve_three_actuators_per_channel_profiles_feel_the_same(tmp_path):
    from tests.e2e.jackutil import require_jack
    from vibsynth.dsp.analysis import analyze
    from vibsynth.dsp.intensity import intensity_level_db
    from vibsynth.formats.basis_file import default_basis

    require_jack()
    basis = default_basis()
    write_true_profiles(tmp_path)
    sims = SimulatedActuator.many(
        [resonance_sos(f0, q, gain, FS) for f0, q, gain in ACTUATORS], noise_rms=1e-5, seed=20, input_index=0
    )
    try:
        one = felt_by_each(tmp_path, sims, "--set", "actuator.profile=sim-ch2")
        each = felt_by_each(tmp_path, sims, "--set", "actuator.channel_profiles=sim-ch{n}")
    finally:
        for sim in sims:
            sim.close()
    result = {}
    for name, ys in (("one profile", one), ("per channel", each)):
        levels = np.array([intensity_level_db(y, fs=FS) for y in ys])
        balances = np.array([analyze(y, fs=FS, basis=basis).balance for y in ys])
        result[name] = levels, balances
        print(f"{name:12s}: 80-200 Hz levels {np.round(levels, 3)} dB, balances {np.round(balances, 3)}")
    levels, balances = result["per channel"]
    raw_levels, raw_balances = result["one profile"]
    print(
        f"one profile: levels {np.ptp(raw_levels):.2f} dB apart, balances {np.ptp(raw_balances):.2f} apart; "
        f"per channel: levels within {np.abs(levels - levels.mean()).max():.3f} dB of their mean "
        f"({levels.mean():.2f} dB), balances within {np.abs(balances - balances.mean()).max():.3f} "
        f"({balances.mean():+.3f})"
    )
    assert np.abs(levels - levels.mean()).max() <= 0.5
    assert np.abs(balances - balances.mean()).max() <= 0.1
    assert abs(levels.mean() - KNOB_LEVEL_DB) <= 0.5 and abs(balances.mean() - 1.0) <= 0.1  # the knobs' feel
    assert np.ptp(raw_levels) > 6.0 and np.ptp(raw_balances) > 0.3  # the test can tell: one profile is not enough
