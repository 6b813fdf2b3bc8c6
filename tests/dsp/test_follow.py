"""The follow tracker in vibration mode and its edges (synthetic, seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.follow import Tracker, TrackerParams, TrackFrames, follow, follow_channels
from vibsynth.dsp.intensity import intensity_frames_db, knob_to_level_db
from vibsynth.dsp.synthesis import synthesize
from vibsynth.errors import ParameterError


def noise(basis, balance, level_db, fs, seconds, seed):
    spec = basis.spectrum_for_balance(balance)
    n = int(seconds * fs)
    return synthesize(spec, fs=fs, n_samples=n, level_db=level_db, rng=np.random.default_rng(seed)).signal


def window_levels(result, x, fs, window=0.1, hop=0.05):
    """The input's 100 ms window levels and the tracked level's power mean over the same windows."""
    ref = intensity_frames_db(x, fs=fs, window_s=window, hop_s=hop)
    tracked = []
    for i in range(ref.size):
        inside = (result.times > i * hop) & (result.times <= i * hop + window)
        tracked.append(10 * np.log10(np.mean(10 ** (result.level_db[inside] / 10))))
    return ref[1:-1], np.array(tracked)[1:-1]  # the reference wraps around at both ends


@pytest.mark.parametrize("fs", [2800.0, 44100.0, 48000.0])
@pytest.mark.parametrize("balance", [-2.0, 0.0, 2.0])
def test_stationary_noise_level_and_balance(basis, fs, balance):
    x = noise(basis, balance, -50.0, fs, 3.0, seed=int(fs) + int(10 * balance))
    r = follow(x, fs, basis=basis)
    ref, tracked = window_levels(r, x, fs)
    assert np.max(np.abs(tracked - ref)) < 1.0
    for t0 in np.arange(0.0, 2.5, 0.5):
        inside = (r.times > t0) & (r.times <= t0 + 0.5)
        assert abs(r.balance[inside].mean() - balance) < 0.3
    # at gain 0 the knob asks the engine for the input's own band level
    loud = r.intensity > 0
    assert np.allclose(r.output_level_db[loud], np.clip(r.level_db[loud], -80.0, -40.0), atol=0.05)


def test_level_steps_are_followed_per_window(basis):
    fs = 48000.0
    levels = [-55.0, -49.0, -55.0, -61.0, -55.0]  # 6 dB steps: real scans move 2-3 dB in 50 ms
    x = np.concatenate([noise(basis, 0.5, lv, fs, 0.6, seed=i) for i, lv in enumerate(levels)])
    r = follow(x, fs, basis=basis)
    ref, tracked = window_levels(r, x, fs)
    assert np.max(np.abs(tracked - ref)) < 1.0
    for t0 in np.arange(0.0, 2.5, 0.5):
        inside = (r.times > t0) & (r.times <= t0 + 0.5)
        assert abs(r.balance[inside].mean() - 0.5) < 0.3
    # a step shows within a hop of its time: latency compensated
    step = np.flatnonzero(r.times >= 0.6)[0]
    after, before = r.level_db[step + 2 : step + 8], r.level_db[step - 8 : step - 2]
    assert 10 * np.log10(np.mean(10 ** (after / 10))) > -52.0 > 10 * np.log10(np.mean(10 ** (before / 10)))


def test_big_level_steps_do_not_swing_the_balance(basis):
    fs = 48000.0
    levels = [-60.0, -45.0, -65.0, -50.0]
    x = np.concatenate([noise(basis, 1.0, lv, fs, 1.0, seed=i) for i, lv in enumerate(levels)])
    r = follow(x, fs, basis=basis)
    for t0 in np.arange(0.0, 4.0, 0.5):
        inside = (r.times > t0) & (r.times <= t0 + 0.5)
        assert abs(r.balance[inside].mean() - 1.0) < 0.3


def test_big_steps_blur_only_the_windows_at_the_step(basis):
    fs = 48000.0
    x = np.concatenate([noise(basis, 0.0, lv, fs, 1.0, seed=i) for i, lv in enumerate([-70.0, -45.0, -65.0])])
    r = follow(x, fs, basis=basis)
    ref, tracked = window_levels(r, x, fs)
    starts = 0.05 * np.arange(1, ref.size + 1)
    near = np.array([min(abs(s - 1.0), abs(s + 0.1 - 1.0), abs(s - 2.0), abs(s + 0.1 - 2.0)) for s in starts]) < 0.012
    assert np.max(np.abs(tracked - ref)[~near]) < 1.0
    # a window ending within 12 ms of a 25 dB step takes a few ms of the loud side through the
    # 10 ms level window: several dB on the quiet side's window
    assert np.max(np.abs(tracked - ref)[near]) < 10.0


def test_output_level_equals_input_level_through_the_knob(basis):
    fs = 8000.0
    x = noise(basis, 0.0, -62.0, fs, 2.0, seed=5)
    r = follow(x, fs, basis=basis)
    expected = 10 * np.log10(np.mean(10 ** (r.output_level_db / 10)))
    assert expected == pytest.approx(10 * np.log10(np.mean(10 ** (r.level_db / 10))), abs=0.05)
    assert knob_to_level_db(float(np.median(r.intensity))) == pytest.approx(-62.0, abs=1.0)
    gained = follow(x, fs, basis=basis, params=TrackerParams(gain_db=6.0))
    assert np.median(gained.output_level_db) == pytest.approx(np.median(r.output_level_db) + 6.0, abs=0.05)


def test_block_size_does_not_change_the_frames(basis, rng):
    fs = 48000.0
    x = noise(basis, -1.0, -50.0, fs, 1.0, seed=3)
    reference = Tracker(fs=fs, params=TrackerParams(), basis=basis)
    whole = TrackFrames.concat([reference.process(x[:4800]), reference.process(x[4800:])])
    tracker = Tracker(fs=fs, params=TrackerParams(), basis=basis)
    cuts = np.concatenate(([4800], np.sort(rng.integers(4801, x.size, 200))))  # the first block sets the offset
    parts = [tracker.process(p) for p in np.split(x, cuts)]
    joined = [np.concatenate([getattr(p, k) for p in parts]) for k in ("end_sample", "level_db", "balance")]
    assert np.array_equal(joined[0], whole.end_sample)
    assert np.allclose(joined[1], whole.level_db, atol=1e-9)
    assert np.allclose(joined[2], whole.balance, atol=1e-9)


def test_live_hop_and_latency_are_small(basis):
    t = Tracker(fs=48000.0, params=TrackerParams(), basis=basis)
    assert 96 <= t.hop <= 256
    assert t.latency < 0.012 * 48000
    # a level step up shows half of its dB step within a hop of the stated latency
    fs = 48000.0
    x = np.concatenate([noise(basis, 0.0, -70.0, fs, 0.5, 1), noise(basis, 0.0, -50.0, fs, 0.5, 2)])
    f = Tracker(fs=fs, params=TrackerParams(), basis=basis).process(x)
    half = f.end_sample[np.flatnonzero(f.level_db > -60.0)[0]]
    assert half - 24000 <= t.latency + t.hop


def test_silence_plays_silence(basis):
    r = follow(np.zeros(48000), 48000.0, basis=basis)
    assert r.silent and np.all(r.intensity == 0) and "silent" in r.notes[0]


def test_dc_makes_no_intensity(basis):
    r = follow(np.full(48000, 0.5), 48000.0, basis=basis)
    assert r.silent and np.all(r.intensity == 0) and not r.onsets
    x = noise(basis, 0.0, -50.0, 48000.0, 1.0, 1)
    shifted = follow(x + 0.3, 48000.0, basis=basis)
    plain = follow(x, 48000.0, basis=basis)
    assert np.allclose(shifted.level_db, plain.level_db, atol=0.01)


def test_nan_and_inf_are_replaced_and_counted(basis):
    x = noise(basis, 0.0, -50.0, 8000.0, 1.0, 1)
    x[100:110] = np.nan
    x[4000] = np.inf
    r = follow(x, 8000.0, basis=basis)
    assert r.nonfinite_samples == 11 and "11 NaN" in " ".join(r.notes)
    assert np.all(np.isfinite(r.intensity)) and np.all(np.isfinite(r.balance))


def test_clipping_is_counted(basis):
    x = noise(basis, 0.0, -20.0, 8000.0, 1.0, 1)
    peak = 0.5 * np.max(np.abs(x))
    r = follow(np.clip(x, -peak, peak), 8000.0, basis=basis)
    assert r.clipped_samples > 10 and "clips" in " ".join(r.notes)
    assert follow(x, 8000.0, basis=basis).clipped_samples == 0


def test_one_sample_input_is_one_clear_error(basis):
    with pytest.raises(ParameterError, match="1 sample"):
        follow(np.ones(1), 48000.0, basis=basis)
    assert len(Tracker(fs=48000.0, params=TrackerParams(), basis=basis).process(np.ones(1))) == 0


def test_eight_channels_at_192k_are_mixed_and_resampled(basis):
    fs = 192000.0
    mono = noise(basis, 1.0, -50.0, fs, 1.5, 7)
    x = np.repeat(mono[:, np.newaxis], 8, axis=1)
    r = follow(x, fs, basis=basis)
    ref = follow(noise(basis, 1.0, -50.0, 48000.0, 1.5, 8), 48000.0, basis=basis)
    assert 10 * np.log10(np.mean(10 ** (r.level_db / 10))) == pytest.approx(-50.0, abs=0.5)
    assert r.balance[r.times > 0.5].mean() == pytest.approx(ref.balance[ref.times > 0.5].mean(), abs=0.3)
    each = follow_channels(x[:, :2], fs, basis=basis)
    assert len(each) == 2 and np.allclose(each[0].level_db, each[1].level_db)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"fs": 1000.0}, "input rate"),
        ({"fs": float("nan")}, "input rate"),
        ({"params": TrackerParams(mode="audio"), "fs": 4000.0}, "audio"),
    ],
)
def test_bad_tracker_arguments(basis, kwargs, match):
    args = {"fs": 48000.0, "params": TrackerParams(), "basis": basis} | kwargs
    with pytest.raises(ParameterError, match=match):
        Tracker(**args)


@pytest.mark.parametrize(
    "field, value", [("mode", "loud"), ("focus", "voice"), ("gain_db", float("nan")), ("hop_ms", 0.0)]
)
def test_bad_params(field, value):
    with pytest.raises(ParameterError, match=field.split("_")[0]):
        TrackerParams(**{field: value})


def test_follow_and_follow_channels_share_one_set_of_options_and_refuse_others(basis):
    rng = np.random.default_rng(11)
    x = 0.01 * rng.standard_normal((24000, 2))
    options = {"mode": "audio", "focus": "effects", "basis": basis, "ceiling_db": -34.0, "range_db": 30.0}
    mixed = follow(x.mean(axis=1), 48000.0, **options)
    assert np.array_equal(follow(x, 48000.0, **options).intensity, mixed.intensity)
    left, right = follow_channels(x, 48000.0, **options)
    assert np.array_equal(left.intensity, follow(x[:, 0], 48000.0, **options).intensity)
    assert (mixed.mode, mixed.focus) == ("audio", "effects")
    with pytest.raises(TypeError, match="unexpected keyword argument 'ceiling'"):
        follow(x, 48000.0, basis=basis, ceiling=-30.0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'foucs'"):
        follow_channels(x, 48000.0, basis=basis, foucs="bass")
