"""Offline rendering of MIDI files: a slow 7-bit CC sweep gives a monotonic t1 trajectory without zipper steps."""

from __future__ import annotations

import mido
import numpy as np
import pytest

from vibsynth.app.midi_render import render_midi_file
from vibsynth.dsp.basis import to_db
from vibsynth.dsp.filterbank import band_power_frames
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis
from vibsynth.settings.config import default_config_data
from vibsynth.settings.typed import settings_of

FS = 8000.0  # bands reach 1 kHz; a low rate keeps the test fast
STEP_S = 0.0625  # one 7-bit CC step every 62.5 ms: a 8 s sweep over 128 values
TICKS_PER_BEAT = 480  # with 120 bpm: 960 ticks per second


@pytest.fixture(scope="module")
def basis():
    return default_basis()


@pytest.fixture(scope="module")
def bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=2.0, levels=29, seed=3))


def make_engine(bank) -> Engine:
    return Engine(bank, channels=1, ceiling_db=-24.0, range_db=40.0, glide_s=0.02)


def write_sweep(path, *, start_s: float = 0.5) -> None:
    """CC 11 = 127 at 0, then CC 74 from 0 to 127, one step every STEP_S."""
    mid = mido.MidiFile(ticks_per_beat=TICKS_PER_BEAT)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.MetaMessage("set_tempo", tempo=500000, time=0))
    track.append(mido.Message("control_change", control=11, value=127, time=0))
    track.append(mido.Message("control_change", control=74, value=0, time=int(start_s * 960)))
    for v in range(1, 128):
        track.append(mido.Message("control_change", control=74, value=v, time=int(STEP_S * 960)))
    mid.save(path)


def config(**midi):
    data = default_config_data()
    data["midi"].update(mode="continuous", **midi)
    return settings_of(data)


def t1_frames(x: np.ndarray, basis) -> np.ndarray:
    frames = band_power_frames(x, fs=FS, window_s=0.1, hop_s=0.05)
    return basis.scores(to_db(frames))[:, 0]


def ideal_ramp(bank, seconds: float, start_s: float = 0.5) -> np.ndarray:
    """The same sweep as continuous piecewise-linear glides (what a perfect smoother would do)."""
    engine = make_engine(bank)
    f = lambda t: int(round(t * FS))  # noqa: E731
    t0, dt = start_s, STEP_S
    engine.submit(SetKnob("intensity", 1.0, None, 0, None))
    engine.submit(SetKnob("balance", -3.5, None, f(t0), None))
    engine.submit(SetKnob("balance", 0.0, None, f(t0 + dt), 64 * dt))
    engine.submit(SetKnob("balance", 3.5, None, f(t0 + 65 * dt), 63 * dt))
    return engine.render(f(seconds))[:, 0]


def test_cc_sweep_renders_monotonic_t1(tmp_path, bank, basis):
    path = tmp_path / "sweep.mid"
    write_sweep(path)
    x, fs = render_midi_file(path, settings=config(), engine=make_engine(bank), seconds=9.0)
    assert fs == FS and x.dtype == np.float32 and x.shape == (int(9.0 * FS), 1)
    assert np.abs(x).max() > 0
    t1 = t1_frames(x[:, 0].astype(np.float64), basis)
    times = 0.05 * np.arange(t1.size) + 0.05
    sweep = (times > 0.6) & (times < 8.4)
    # half-second means rise strictly over the whole sweep
    seg = t1[sweep][: (sweep.sum() // 10) * 10].reshape(-1, 10).mean(axis=1)
    assert np.all(np.diff(seg) > 0), seg
    # and frame by frame t1 follows the requested balance
    requested = np.clip((times[sweep] - 0.5) / (127 * STEP_S), 0, 1)
    assert np.corrcoef(t1[sweep], requested)[0, 1] > 0.98
    assert t1[sweep][-20:].mean() - t1[sweep][:20].mean() > 5.0


def _residual_db(x: np.ndarray, ideal: np.ndarray, start: int, stop: int) -> float:
    err = x[start:stop] - ideal[start:stop]
    return float(10 * np.log10((np.mean(err**2) + 1e-30) / np.mean(ideal[start:stop] ** 2)))


def test_cc_sweep_has_no_zipper_steps(tmp_path, bank):
    """The rendered 7-bit sweep equals a continuous ramp: no staircase, no clicks at step instants.

    Both renders read the same bank at the same positions, so any difference is the
    knob trajectory. With the adaptive CC smoothing the residual is far below the
    signal; with plain 20 ms glides (``cc_glide_max_ms: 0``) the staircase shows as a
    residual tens of dB higher, so the test can fail.
    """
    path = tmp_path / "sweep.mid"
    write_sweep(path)
    seconds = 9.0
    ideal = ideal_ramp(bank, seconds)
    smooth, _ = render_midi_file(path, settings=config(), engine=make_engine(bank), seconds=seconds)
    stairs, _ = render_midi_file(path, settings=config(cc_glide_max_ms=0), engine=make_engine(bank), seconds=seconds)
    a, b = int(0.6 * FS), int(8.4 * FS)
    smooth_db = _residual_db(smooth[:, 0], ideal, a, b)
    stairs_db = _residual_db(stairs[:, 0], ideal, a, b)
    print(f"residual vs ideal ramp: adaptive {smooth_db:.1f} dB, 20 ms glides {stairs_db:.1f} dB")
    assert smooth_db < -60.0, smooth_db
    assert stairs_db > smooth_db + 20.0, (smooth_db, stairs_db)
    # no sample-to-sample jump at the step instants beyond what the ideal ramp has
    steps = np.abs(np.diff(smooth[a:b, 0]))
    ideal_steps = np.abs(np.diff(ideal[a:b]))
    assert steps.max() <= ideal_steps.max() * 1.01 + 1e-6


def test_notes_gate_the_texture_in_a_file(tmp_path, bank):
    mid = mido.MidiFile(ticks_per_beat=TICKS_PER_BEAT)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.Message("note_on", note=60, velocity=127, time=480))  # 0.5 s
    track.append(mido.Message("note_on", note=64, velocity=100, time=480))  # 1.0 s, stacked
    track.append(mido.Message("note_off", note=60, time=480))  # 1.5 s: still sounding
    track.append(mido.Message("note_off", note=64, time=480))  # 2.0 s: release
    path = tmp_path / "notes.mid"
    mid.save(path)
    data = default_config_data()
    data["midi"].update(mode="gate", release_ms=100.0)
    x, _ = render_midi_file(path, settings=settings_of(data), engine=make_engine(bank))
    rms = lambda t0, t1: float(np.sqrt(np.mean(x[int(t0 * FS) : int(t1 * FS), 0] ** 2)))  # noqa: E731
    assert x.shape[0] == int(round((2.0 + 0.1 + 0.25) * FS))
    assert rms(0.0, 0.45) == 0.0
    assert rms(0.6, 0.95) > 0 and rms(1.1, 1.95) > 0
    assert rms(1.6, 1.95) > 0.3 * rms(0.6, 0.95)
    assert rms(2.15, 2.3) == 0.0


def test_render_through_service_build_engine(tmp_path):
    from vibsynth.app import service
    from vibsynth.settings.config import load_config

    path = tmp_path / "short.mid"
    mid = mido.MidiFile(ticks_per_beat=TICKS_PER_BEAT)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.Message("note_on", note=60, velocity=127, time=0))
    track.append(mido.Message("note_off", note=60, time=480))
    mid.save(path)
    cfg = load_config(overrides={"bank": {"levels": 5, "loop_seconds": 1.0, "cache_dir": ""}, "audio": {"rate": 8000}})
    assert hasattr(service, "build_engine")
    x, fs = render_midi_file(path, settings=cfg.settings)
    assert fs == 8000 and x.shape[0] == int(round((0.5 + 0.15 + 0.25) * fs))
    assert np.abs(x[: int(0.4 * fs)]).max() > 0
