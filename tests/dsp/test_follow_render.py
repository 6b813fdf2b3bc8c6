"""Vibration mode end to end: the tracked knobs rendered by the engine match the input per window.

The input is noise of known spectra or a non-stationary scan built from the HaTT texture models of
../shared (one texture's models at rising scanning speed, then the next texture, crossfaded over
50 ms as a stylus speeds up or crosses a seam; low-passed at 1 kHz, the actuator band). The
engine renders the trajectory offline at several bank seeds: one render of noise scatters about
1 dB per 100 ms window by itself, the expected output level is the mean over seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.app.render import ArrayCollector, Cue, render
from vibsynth.app.service import build_engine
from vibsynth.dsp.basis import to_db
from vibsynth.dsp.filterbank import band_power_frames
from vibsynth.dsp.follow import FollowResult, TrackerParams, follow
from vibsynth.dsp.intensity import intensity_frames_db
from vibsynth.dsp.synthesis import synthesize
from vibsynth.engine.commands import SetKnob
from vibsynth.formats.psd import read_psd_table
from vibsynth.settings.config import load_config

FS = 8000.0
SEEDS = tuple(range(1, 33))  # the mean of 32 renders scatters ~0.25 dB per window


def rendered(result: FollowResult, basis, n: int, seed: int, ceiling_db: float = -40.0) -> np.ndarray:
    """The engine playing a follow result (a glide of one hop per frame), mono at FS."""
    overrides = {
        "audio.rate": int(FS),
        "audio.channels": 1,
        "knobs.initial_intensity": 0.0,
        "knobs.ceiling_db": ceiling_db,
        "bank.cache_dir": "",
        "bank.seed": seed,
        "bank.levels": 29,
    }
    engine = build_engine(load_config(None, overrides=overrides, user_file=False).settings, basis=basis)
    cues = []
    for t, k, b in zip(result.times, result.intensity, result.balance):
        frame = int(round(t * FS))
        cues.append(Cue(frame, SetKnob("intensity", float(k), glide_s=result.hop_s)))
        cues.append(Cue(frame, SetKnob("balance", float(b), glide_s=result.hop_s)))
    return render(engine, n, ArrayCollector(n, 1), timeline=cues).output[:, 0].astype(np.float64)


def expected_levels(x, result, basis, ceiling_db=-40.0, gain_db=0.0):
    """Input and mean-over-seeds output band level per 100 ms window (50 ms hop), edges dropped."""
    want = intensity_frames_db(x, fs=FS)[2:-2] + gain_db
    power = np.mean(
        [10 ** (intensity_frames_db(rendered(result, basis, x.size, s, ceiling_db), fs=FS) / 10) for s in SEEDS], axis=0
    )
    return want, 10 * np.log10(power)[2:-2]


def window_balance(x, basis, window_s=0.5):
    t1 = basis.scores(to_db(band_power_frames(x, fs=FS, window_s=window_s, hop_s=window_s)))[:, 0]
    return np.asarray(basis.balance_from_t1(t1))


def tracked_balance(result, n_windows, window_s=0.5):
    return np.array(
        [
            result.balance[(result.times > i * window_s) & (result.times <= (i + 1) * window_s)].mean()
            for i in range(n_windows)
        ]
    )


def noise(basis, balance, level_db, seconds, seed):
    spec = basis.spectrum_for_balance(balance)
    return synthesize(
        spec, fs=FS, n_samples=int(seconds * FS), level_db=level_db, rng=np.random.default_rng(seed)
    ).signal


@pytest.mark.parametrize("balance", [-1.0, 0.0, 1.0])
def test_stationary_noise_renders_at_its_own_level_and_balance(basis, balance):
    x = noise(basis, balance, -55.0, 3.0, seed=11)
    r = follow(x, FS, basis=basis)
    want, got = expected_levels(x, r, basis)
    assert np.max(np.abs(got - want)) < 1.0
    out = rendered(r, basis, x.size, seed=5)
    assert np.max(np.abs(window_balance(out, basis) - window_balance(x, basis))) < 0.3


def test_level_steps_render_per_window(basis):
    levels = [-60.0, -54.0, -48.0, -54.0, -62.0]
    x = np.concatenate([noise(basis, 0.3, lv, 0.6, seed=i) for i, lv in enumerate(levels)])
    r = follow(x, FS, basis=basis)
    want, got = expected_levels(x, r, basis)
    assert np.max(np.abs(got - want)) < 1.0


def hatt_scan(path, basis, names, segment_s=0.35, fade_s=0.05, seed=0):
    """A scan from real texture models: each texture's models in order of speed, crossfaded."""
    table = read_psd_table(path)
    labels = np.array(table.labels)
    rng = np.random.default_rng(seed)
    n_seg, n_fade = int(segment_s * FS), int(fade_s * FS)
    freqs = np.fft.rfftfreq(n_seg + n_fade, 1 / FS)
    pieces = []
    for name in names:
        rows = np.flatnonzero(labels == name)
        speeds = np.array([float(table.meta[i]["speed_mm_s"]) for i in rows])
        for i in rows[np.argsort(speeds)][::3]:
            psd = np.interp(freqs, table.freqs_hz, table.psd[i], left=table.psd[i][0], right=0.0)
            psd /= 1 + (freqs / 1000.0) ** 8  # the actuator band: above 1 kHz the models are sensor noise
            spectrum = np.sqrt(psd * FS * (n_seg + n_fade) / 2) * np.exp(2j * np.pi * rng.random(freqs.size))
            pieces.append(np.fft.irfft(spectrum, n_seg + n_fade))
    ramp = np.sin(0.5 * np.pi * np.arange(n_fade) / n_fade) ** 2
    out = pieces[0]
    for p in pieces[1:]:
        head = out[-n_fade:] * (1 - ramp) + p[:n_fade] * ramp
        out = np.concatenate((out[:-n_fade], head, p[n_fade:]))
    return out


@pytest.mark.shared
def test_real_scan_from_shared_texture_models(basis, hatt_psd):
    x = hatt_scan(hatt_psd, basis, ["Brick 2", "Cork", "Aluminum Foil"])
    levels = intensity_frames_db(x, fs=FS)
    assert np.std(levels) > 2.0  # non-stationary: the paper's metric
    gain = -41.0 - float(np.max(levels))  # into the knob range (-80 .. -40 dB)
    assert np.min(levels) + gain > -80.0
    r = follow(x, FS, basis=basis, params=TrackerParams(gain_db=gain))
    ref = levels[1:-1]
    tracked = np.array(
        [
            10 * np.log10(np.mean(10 ** (r.level_db[(r.times > i * 0.05) & (r.times <= i * 0.05 + 0.1)] / 10)))
            for i in range(levels.size)
        ]
    )[1:-1]
    assert np.max(np.abs(tracked - ref)) < 1.0
    want, got = expected_levels(x, r, basis, gain_db=gain)
    assert np.max(np.abs(got - want)) < 1.0
    truth = window_balance(x, basis)
    assert np.max(np.abs(tracked_balance(r, truth.size) - truth)) < 0.3
