"""Codec: stationary sets, segmented trajectories, quantiser, schedule, quality (synthetic, seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.basis import to_db
from vibsynth.dsp.codec import (
    Quantizer,
    decode_stationary,
    encode_stationary,
    encode_trajectory,
    knob_schedule,
    quality,
)
from vibsynth.dsp.filterbank import band_powers
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.dsp.synthesis import synthesize
from vibsynth.errors import ParameterError

FS = 2800.0


def noise(basis, t1, level, seed, seconds=5.0):
    spec = basis.mean_db + t1 * basis.v1
    return synthesize(spec, fs=FS, n_samples=int(seconds * FS), level_db=level, rng=np.random.default_rng(seed)).signal


def test_stationary_set_round_trip(basis):
    xs = [noise(basis, t, lv, s, 2.0) for s, (t, lv) in enumerate([(-25, -35), (0, -30), (30, -28)])]
    spectra = np.array([to_db(band_powers(x, fs=FS)) for x in xs])
    levels = np.array([intensity_level_db(x, fs=FS) for x in xs])
    code = encode_stationary(spectra, levels, basis=basis)
    assert code.n_values == 30 + 30 + 2 * 3 and code.n_values_paper == 63
    assert np.allclose(code.t1, [-25, 0, 30], atol=0.05)
    out = decode_stationary(code, fs=FS, n_samples=5600, rng=np.random.default_rng(0))
    for y, lv, t in zip(out, levels, code.t1):
        assert intensity_level_db(y, fs=FS) == pytest.approx(lv, abs=0.01)
        assert basis.scores(to_db(band_powers(y, fs=FS)))[0] == pytest.approx(t, abs=0.05)


def test_stationary_recording_is_one_segment_with_unbiased_values(basis):
    x = noise(basis, 12.0, -30.0, 3, 10.0)
    traj = encode_trajectory(x, fs=FS, basis=basis)
    assert traj.n_frames == 199
    assert np.unique(traj.level_db).size == 1 and np.unique(traj.t1).size == 1
    assert traj.level_db[0] == pytest.approx(-30.0, abs=0.2)
    assert traj.t1[0] == pytest.approx(12.0, abs=0.5)
    raw = encode_trajectory(x, fs=FS, basis=basis, segment=False)
    # Per-window values are noisy and t1 biased (why segments are the default).
    assert np.std(raw.level_db) > 0.3 and abs(np.mean(raw.t1) - 12.0) > 1.0


@pytest.mark.parametrize("seed", range(4))
def test_no_false_segments_in_stationary_noise(basis, seed):
    traj = encode_trajectory(noise(basis, 5.0 * seed - 10, -30.0, 10 + seed, 10.0), fs=FS, basis=basis)
    assert np.unique(traj.level_db).size == 1


def test_intensity_step_lands_in_the_right_window(basis):
    half = int(5 * FS)
    x = np.concatenate([noise(basis, 0, -36, 1, 5.0), noise(basis, 0, -26, 2, 5.0)])
    traj = encode_trajectory(x, fs=FS, basis=basis)
    changes = np.flatnonzero(np.diff(traj.level_db)) + 1
    assert changes.size == 1
    # The first window after the change: window 99 is centred on the step (sample 14000).
    centre_of_step = (half - traj.window / 2) / traj.hop
    assert abs(changes[0] - centre_of_step) <= 1.0
    assert traj.level_db[0] == pytest.approx(-36, abs=0.3) and traj.level_db[-1] == pytest.approx(-26, abs=0.3)


def test_balance_step_is_a_t1_change(basis):
    x = np.concatenate([noise(basis, -20, -30, 1, 4.0), noise(basis, 20, -30, 2, 4.0)])
    traj = encode_trajectory(x, fs=FS, basis=basis)
    assert traj.t1[0] == pytest.approx(-20, abs=2.0) and traj.t1[-1] == pytest.approx(20, abs=2.0)


def test_silence_is_coded_as_silent(basis):
    x = np.concatenate([noise(basis, 0, -30, 1, 2.0), np.zeros(int(2 * FS)), noise(basis, 0, -30, 2, 2.0)])
    traj = encode_trajectory(x, fs=FS, basis=basis)
    assert traj.silent[42:76].all() and not traj.silent[:30].any() and not traj.silent[-30:].any()
    q = Quantizer.fit(traj)
    level, _ = q.decode(*q.encode(traj.level_db, traj.t1))
    assert np.array_equal(np.isfinite(level), np.isfinite(traj.level_db))


def test_quantiser_error_is_half_a_step(rng):
    q = Quantizer(8, -60.0, -20.0, -50.0, 50.0)
    lv = rng.uniform(-60, -20, 1000)
    t1 = rng.uniform(-50, 50, 1000)
    dl, dt = q.decode(*q.encode(lv, t1))
    assert q.level_step == pytest.approx(40 / 254) and q.t1_step == pytest.approx(100 / 255)
    assert np.max(np.abs(dl - lv)) <= q.level_step / 2 + 1e-9
    assert np.max(np.abs(dt - t1)) <= q.t1_step / 2 + 1e-9
    with pytest.raises(ParameterError, match="bits"):
        Quantizer(1, 0, 1, 0, 1)
    with pytest.raises(ParameterError, match="range"):
        Quantizer(8, 0, 0, 0, 1)


def test_schedule_glides_between_window_centres(basis):
    x = np.concatenate([noise(basis, 0, -36, 1, 5.0), noise(basis, 0, -26, 2, 5.0)])
    traj = encode_trajectory(x, fs=FS, basis=basis)
    ev = knob_schedule(traj, basis=basis, out_fs=48000.0, ceiling_db=-20.0, range_db=40.0)
    assert len(ev) == 2 and ev[0].frame == 0 and ev[0].glide_s == 0
    k = int(np.flatnonzero(np.diff(traj.level_db))[0]) + 1
    assert ev[1].frame == round(traj.centres_s()[k - 1] * 48000) and ev[1].glide_s == pytest.approx(0.05)
    assert ev[1].intensity == pytest.approx(1 + (traj.level_db[-1] + 20) / 40)


def test_quality_of_identical_signals_is_perfect(basis):
    x = noise(basis, 5, -30, 4, 3.0)
    q = quality(x, x, fs=FS, basis=basis)
    assert q.band_error_rms_db < 1e-9 and q.dissimilarity < 1e-9 and q.window_level_rms_db < 1e-9
    assert q.non_stationarity_decoded_db == pytest.approx(q.non_stationarity_original_db)
    q2 = quality(x, x * 0.5, fs=FS, basis=basis, offset_db=20 * np.log10(2))
    assert abs(q2.level_error_db) < 1e-9


def test_bad_input_is_rejected(basis):
    with pytest.raises(ParameterError, match="silent"):
        encode_trajectory(np.zeros(5600), fs=FS, basis=basis)
    with pytest.raises(ParameterError, match="hop"):
        encode_trajectory(np.ones(5600), fs=FS, basis=basis, hop_s=0.2)


def test_segment_error_names_how_far_segments_flatten_a_ramp(basis):
    """A 30 dB ramp (a finger pressing harder) is not stationary: one segment is ~20 dB off its ends."""
    from vibsynth.dsp.follow import window_analysis

    fs = 2800.0
    x = synthesize(basis.mean_db, fs=fs, n_samples=int(6 * fs), level_db=-40.0, rng=np.random.default_rng(0)).signal
    ramp = x * 10 ** (np.linspace(-30, 0, x.size) / 20)
    seg = encode_trajectory(ramp, fs=fs, basis=basis)
    measured = window_analysis(ramp, fs=fs, basis=basis, window_s=seg.window_s, hop_s=seg.hop_s)[3]
    loud = np.isfinite(seg.level_db)
    assert seg.window_level_error_db == pytest.approx(np.max(np.abs(seg.level_db[loud] - measured[loud])))
    assert seg.window_level_error_db > 10.0
    per_window = encode_trajectory(ramp, fs=fs, basis=basis, segment=False)
    assert per_window.window_level_error_db == pytest.approx(0.0, abs=1e-9)
