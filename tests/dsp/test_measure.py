"""Swept-sine measurement: a known impulse response and latency are recovered (seeded noise)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from vibsynth.dsp.measure import (
    SweepPlan,
    band_response_db,
    clipped_samples,
    deconvolve,
    exp_sweep,
    inverse_filter,
    ir_peak,
    measure_recording,
    response_freqs,
    response_loss,
    sweep_frequency,
)
from vibsynth.errors import ParameterError

FS = 48000.0


def resonance(f0: float = 65.0, q: float = 3.0, gain_db: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A voice coil's acceleration: a 2nd-order high-pass resonance (RBJ biquad)."""
    w0 = 2 * math.pi * f0 / FS
    alpha = math.sin(w0) / (2 * q)
    c = math.cos(w0)
    b = np.array([(1 + c) / 2, -(1 + c), (1 + c) / 2]) * 10 ** (gain_db / 20)
    a = np.array([1 + alpha, -2 * c, 1 - alpha])
    return b / a[0], a / a[0]


def record(plan: SweepPlan, b, a, *, delay: int, noise: float, seed: int, extra: float = 0.3) -> np.ndarray:
    x = plan.stimulus()
    n = x.size + int(extra * FS)
    y = np.zeros(n)
    out = signal.lfilter(b, a, x)
    y[delay : delay + out.size] = out[: n - delay]
    return y + noise * np.random.default_rng(seed).standard_normal(n)


def truth_db(b, a, freqs):
    _, h = signal.freqz(b, a, worN=freqs, fs=FS)
    return 20 * np.log10(np.abs(h))


def test_sweep_is_exponential_and_its_inverse_filter_makes_an_impulse():
    x = exp_sweep(FS, 10.0, 1000.0, 2.0)
    assert x.size == 96000 and np.max(np.abs(x)) <= 1.0
    # instantaneous frequency doubles in equal times: zero crossings per 10 ms grow
    early = np.count_nonzero(np.diff(np.signbit(x[4800:9600])))
    late = np.count_nonzero(np.diff(np.signbit(x[86400:91200])))
    assert late > 20 * early
    inv = inverse_filter(x, FS, 10.0, 1000.0)
    d = signal.fftconvolve(x, inv)
    k = int(np.argmax(np.abs(d)))
    assert k == x.size - 1
    assert abs(d[k]) > 20 * np.percentile(np.abs(d), 99)


@pytest.mark.parametrize("delay", [0, 1, 517, 4801])
def test_known_impulse_response_and_latency_recovered(delay):
    rng = np.random.default_rng(delay)
    sweep = exp_sweep(FS, 5.0, 2000.0, 1.0)
    # latency: a pure delay and gain, with noise, comes back to the sample
    y = 0.3 * np.concatenate([np.zeros(delay), sweep, np.zeros(12000 - delay)])
    y += 1e-3 * rng.standard_normal(y.size)
    assert round(ir_peak(deconvolve(y, sweep, FS, 5.0, 2000.0), search=slice(0, 6000))) == delay
    # the IR: a random decaying FIR comes back through the 5-2000 Hz band limit
    taps = np.zeros(200)
    taps[0] = 0.5
    taps[1:] = 0.05 * rng.standard_normal(199) * np.exp(-np.arange(1, 200) / 30)
    y = np.zeros(sweep.size + 12000)
    out = np.convolve(sweep, taps)
    y[delay : delay + out.size] = out
    ir = deconvolve(y, sweep, FS, 5.0, 2000.0)
    freqs = np.array([20.0, 100.0, 500.0, 1000.0])
    got = np.fft.rfft(np.roll(ir, 24000 - delay)[:48000], 1 << 16)  # the limit's ringing on both sides
    want = np.fft.rfft(np.concatenate([np.zeros(24000), taps]), 1 << 16)
    bins = np.round(freqs * (1 << 16) / FS).astype(int)
    assert np.allclose(20 * np.log10(np.abs(got[bins] / want[bins])), 0.0, atol=0.05)
    assert np.allclose(np.angle(got[bins] / want[bins]), 0.0, atol=0.01)


def test_fractional_latency_is_refined():
    sweep = exp_sweep(FS, 5.0, 2000.0, 1.0)
    # a delay of 300.5 samples by a half-sample (Lagrange-free) FIR: the mean of two delays
    y = np.zeros(sweep.size + 2000)
    y[300 : 300 + sweep.size] += 0.5 * sweep
    y[301 : 301 + sweep.size] += 0.5 * sweep
    ir = deconvolve(y, sweep, FS, 5.0, 2000.0)
    assert ir_peak(ir, search=slice(0, 1000)) == pytest.approx(300.5, abs=0.05)


def test_resonant_actuator_measured_within_a_tenth_of_a_db_with_noise():
    plan = SweepPlan(fs=FS, seconds=3.0, n_sweeps=3)
    b, a = resonance(65.0, 3.0, gain_db=-6.0)
    m = measure_recording(record(plan, b, a, delay=517, noise=3e-4, seed=1), plan)
    sel = (m.freqs >= 20) & (m.freqs <= 800)
    err = m.response_db - truth_db(b, a, m.freqs)
    assert np.max(np.abs(err[sel])) < 0.1
    assert np.max(np.abs(err)) < 0.3  # 10-1000 Hz
    assert round(m.latency) == 517
    assert m.repeatability_db < 0.1
    assert m.snr_in(20, 800) > 40
    assert m.noise_rms_db == pytest.approx(20 * math.log10(3e-4), abs=0.3)
    assert m.clipped == 0
    # the 30 bands follow the fine response: the resonance's band is the loudest
    assert m.band_db.shape == (30,)
    assert 50 < [f for f, _ in sorted(zip(np.geomspace(10, 1000, 30), m.band_db), key=lambda p: -p[1])][0] < 90


def test_snr_follows_the_noise_and_repeatability_sees_a_burst():
    plan = SweepPlan(fs=FS, seconds=2.0, n_sweeps=3)
    b, a = resonance()
    quiet = measure_recording(record(plan, b, a, delay=10, noise=1e-5, seed=2), plan)
    loud = measure_recording(record(plan, b, a, delay=10, noise=1e-3, seed=2), plan)
    assert np.median(quiet.snr_db - loud.snr_db) == pytest.approx(40.0, abs=1.5)
    plan = SweepPlan(fs=FS, seconds=2.0, n_sweeps=2)
    y = record(plan, b, a, delay=10, noise=1e-5, seed=3)
    start = plan.starts()[1] + plan.sweep_samples // 2
    y[start : start + 9600] += 0.3 * np.random.default_rng(4).standard_normal(9600)  # a knock mid-sweep
    knocked = measure_recording(y, plan)
    assert knocked.repeatability_db > 0.5 > 0.1 > quiet.repeatability_db


def test_clipping_counted():
    x = np.array([0.0, 0.5, 0.995, -1.0, 0.2])
    assert clipped_samples(x) == 2


def test_band_response_of_a_flat_response_is_flat():
    f = response_freqs()
    assert np.allclose(band_response_db(f, np.full(f.size, -12.0)), -12.0)


def test_plan_and_recording_checked():
    with pytest.raises(ParameterError):
        SweepPlan(fs=FS, n_sweeps=0)
    with pytest.raises(ParameterError):
        SweepPlan(fs=FS, level=1.5)
    with pytest.raises(ParameterError):
        SweepPlan(fs=2000.0, f2=2000.0)
    plan = SweepPlan(fs=FS, seconds=1.0, n_sweeps=1)
    with pytest.raises(ParameterError, match="at least"):
        measure_recording(np.zeros(100), plan)
    bad = np.zeros(plan.stimulus().size + 48000)
    bad[5] = np.nan
    with pytest.raises(ParameterError, match="NaN"):
        measure_recording(bad, plan)


def test_three_sweeps_outvote_a_knocked_one():
    plan = SweepPlan(fs=FS, seconds=2.0, n_sweeps=3)
    b, a = resonance()
    y = record(plan, b, a, delay=10, noise=1e-5, seed=5)
    start = plan.starts()[1] + plan.sweep_samples // 2
    y[start : start + 9600] += 0.3 * np.random.default_rng(6).standard_normal(9600)
    m = measure_recording(y, plan)
    sel = (m.freqs >= 20) & (m.freqs <= 800)
    assert np.max(np.abs(m.response_db - truth_db(b, a, m.freqs))[sel]) < 0.1
    assert m.repeatability_db < 0.1
    assert np.max(np.abs(m.sweeps_db[1] - m.response_db)[sel]) > 0.5  # the knocked sweep itself is off


def test_majority_spread_and_combination():
    from vibsynth.dsp.measure import combine_sweeps_db, majority_spread_db

    v = np.array([[0.0], [0.2], [5.0]])
    assert majority_spread_db(v)[0] == pytest.approx(0.2)
    assert combine_sweeps_db(v)[0] == pytest.approx(0.2)
    assert majority_spread_db(v[:2])[0] == pytest.approx(0.2)
    assert combine_sweeps_db(np.array([[0.0], [10 * np.log10(3)]]))[0] == pytest.approx(10 * np.log10(2))


def cut(plan: SweepPlan, y: np.ndarray, *, sweep: int, seconds: float, delay: int) -> np.ndarray:
    """The recording with its response gone (silence, the noise left) from ``seconds`` into ``sweep`` on."""
    out = y.copy()
    at = plan.starts()[sweep - 1] + delay + int(round(seconds * FS))
    b, a = resonance()
    clean = record(plan, b, a, delay=delay, noise=0.0, seed=0)
    out[at:] -= clean[at:]  # the same noise, no actuator: a lost cable, not a quieter room
    return out


@pytest.mark.parametrize(
    ("seconds", "noise", "sweep", "at"),
    [
        (1.0, 1e-4, 2, 0.5),  # the case: half a second into the second sweep
        (1.0, 1e-3, 3, 0.3),
        (1.0, 1e-3, 2, 0.9),  # near a sweep's top
        (4.0, 1e-4, 2, 0.5),  # the default sweep: at 10.6 Hz, low on a voice coil's slope
        (4.0, 1e-4, 1, 2.0),  # in the first sweep: the later sweeps tell what was missed
    ],
)
def test_a_response_lost_mid_sweep_is_found_with_its_sweep_time_and_frequency(seconds, noise, sweep, at):
    plan = SweepPlan(fs=FS, seconds=seconds, n_sweeps=3)
    b, a = resonance()
    delay = 480
    y = cut(plan, record(plan, b, a, delay=delay, noise=noise, seed=7), sweep=sweep, seconds=at, delay=delay)
    m = measure_recording(y, plan, max_latency_s=0.45)
    loss = m.loss
    assert loss is not None and loss.sweep == sweep, loss
    assert loss.seconds == pytest.approx(at, abs=0.03)
    assert loss.freq_hz == pytest.approx(float(sweep_frequency(plan, at)), rel=0.05)
    assert loss.exact == (sweep > 1)  # a first sweep's loss is known from the next sweep's start on
    if sweep > 1:
        assert (loss.missed_sweep, loss.missed_seconds) == pytest.approx((sweep, at), abs=0.05)
    else:
        assert loss.missed_sweep == 2
    assert response_loss(y, plan, m.latency) == loss


def test_a_response_too_weak_to_hear_where_it_stopped_is_placed_between_two_points():
    # Loud noise: the voice coil's 5-20 Hz (30-50 dB down) is under it, so a loss 0.5 s into the second
    # sweep (10.6 Hz) is known only from where the response should have been heard again.
    plan = SweepPlan(fs=FS, seconds=4.0, n_sweeps=3)
    b, a = resonance()
    y = cut(plan, record(plan, b, a, delay=480, noise=3.5e-3, seed=8), sweep=2, seconds=0.5, delay=480)
    loss = measure_recording(y, plan, max_latency_s=0.45).loss
    assert loss is not None and not loss.exact
    assert loss.sweep == 1 and loss.seconds > 3.5  # heard up to sweep 1's top end
    assert loss.missed_sweep == 2 and 0.5 < loss.missed_seconds < 2.0  # missed once the coil should be heard
    assert loss.missed_freq_hz == pytest.approx(float(sweep_frequency(plan, loss.missed_seconds)))


def test_no_loss_in_a_whole_a_weak_a_dropped_out_or_a_silent_recording():
    plan = SweepPlan(fs=FS, seconds=1.0, n_sweeps=3)
    b, a = resonance()
    whole = record(plan, b, a, delay=480, noise=1e-3, seed=9)
    assert measure_recording(whole, plan, max_latency_s=0.45).loss is None
    # an actuator that gives nothing above 300 Hz: every sweep falls silent at the same point
    clean = record(plan, b, a, delay=480, noise=0.0, seed=9)
    top_less = whole - clean + signal.sosfilt(signal.butter(8, 300.0, fs=FS, output="sos"), clean)
    assert measure_recording(top_less, plan, max_latency_s=0.45).loss is None
    # 60 ms dropped mid-sweep, then the response is back: not lost
    dropped = whole.copy()
    at = plan.starts()[1] + 480 + 24000
    dropped[at : at + 2880] = 1e-3 * np.random.default_rng(10).standard_normal(2880)
    assert measure_recording(dropped, plan, max_latency_s=0.45).loss is None
    # a loss in the last sweep's last 0.1 s: too little missed to tell from its fade
    end = cut(plan, whole, sweep=3, seconds=0.92, delay=480)
    assert measure_recording(end, plan, max_latency_s=0.45).loss is None
    # nothing came back at all: no loss (the no-signal check says that)
    silent = 1e-3 * np.random.default_rng(11).standard_normal(whole.size)
    assert measure_recording(silent, plan, max_latency_s=0.45).loss is None
