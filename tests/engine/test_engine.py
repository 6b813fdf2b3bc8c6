"""Engine: levels, glide, crossfade, limiter, mute, scheduling, block invariance, no allocation, threads."""
from __future__ import annotations

import threading
import tracemalloc

import numpy as np
import pytest

from vibsynth.dsp.intensity import intensity_level_db, knob_to_level_db
from vibsynth.engine.commands import Panic, SetGlide, SetKnob, SetMute
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError


def make(bank, **kw):
    kw.setdefault("max_block", 1024)
    return Engine(bank, **kw)


def test_silent_until_a_control_arrives(small_bank):
    out = make(small_bank, channels=2).render(4000)
    assert out.shape == (4000, 2) and out.dtype == np.float32
    assert not out.any()


@pytest.mark.parametrize("knob,balance", [(0.5, 0.0), (0.9, -1.0), (0.2, 1.0)])
def test_intensity_level_follows_knob(small_bank, knob, balance):
    e = make(small_bank, initial_intensity=knob, initial_balance=balance, ceiling_db=-40, range_db=40)
    x = e.render(small_bank.n_samples)[:, 0].astype(np.float64)
    assert intensity_level_db(x, fs=e.fs) == pytest.approx(knob_to_level_db(knob, ceiling_db=-40, range_db=40), abs=0.05)


def test_crossfade_is_linear_mix_of_adjacent_levels(small_bank):
    b = small_bank.balances
    target = b[10] + 0.3 * (b[11] - b[10])
    e = make(small_bank, initial_intensity=1.0, initial_balance=target, ceiling_db=-60, range_db=40)
    y = e.render(500)[:, 0].astype(np.float64)
    x = small_bank.signals.astype(np.float64)
    mix = 0.7 * x[10, :500] + 0.3 * x[11, :500]
    gain = y @ mix / (mix @ mix)
    np.testing.assert_allclose(y, gain * mix, atol=1e-6 * np.abs(y).max() + 1e-9)
    assert gain == pytest.approx(10 ** (-60 / 20), rel=1e-5)


def test_linear_glide_reaches_target_in_glide_time(small_bank):
    fs = small_bank.fs
    e = make(small_bank, glide_s=0.0)
    e.submit(SetGlide(0.02))
    e.submit(SetKnob("intensity", 0.8))
    n = int(round(0.02 * fs))
    e.render(n // 2)
    assert e.knob_values()[0][0] == pytest.approx(0.4, abs=1e-9)
    e.render(n - n // 2)
    assert e.knob_values()[0][0] == pytest.approx(0.8, abs=1e-12)
    # After the glide the output equals a jumped engine's, sample for sample.
    ref = make(small_bank, initial_intensity=0.8)
    ref.render(n)
    np.testing.assert_array_equal(e.render(300), ref.render(300))


def test_glide_zero_jumps_on_the_sample(small_bank):
    e = make(small_bank, glide_s=0.0)
    e.submit(SetKnob("intensity", 0.7, at_frame=1000))
    y = e.render(2000)[:, 0]
    assert not y[:1000].any()
    assert y[1000] != 0
    ref = make(small_bank, initial_intensity=0.7)
    np.testing.assert_array_equal(y[1000:], ref.render(2000)[1000:, 0])


def test_scheduled_command_applies_at_exact_sample_across_blocks(small_bank):
    e = make(small_bank, glide_s=0.0)
    e.submit(SetKnob("intensity", 0.5, at_frame=1234))
    y = np.concatenate([e.render(100)[:, 0] for _ in range(20)])
    assert np.flatnonzero(y)[0] == 1234


def test_late_command_applies_at_block_start_and_is_counted(small_bank):
    e = make(small_bank, glide_s=0.0)
    e.render(500)
    e.submit(SetKnob("intensity", 0.5, at_frame=100))
    y = e.render(10)[:, 0]
    assert y[0] != 0 and e.stats.late_commands == 1


def test_channels_are_independent(small_bank):
    e = make(small_bank, channels=3, glide_s=0.0)
    e.submit(SetKnob("intensity", 0.6, channels=(1,)))
    y = e.render(800)
    assert not y[:, 0].any() and not y[:, 2].any() and y[:, 1].any()


def test_channels_are_decorrelated(small_bank):
    e = make(small_bank, channels=4, initial_intensity=0.5)
    y = e.render(small_bank.n_samples).astype(np.float64)
    r = np.corrcoef(y.T)
    assert np.abs(r[np.triu_indices(4, 1)]).max() < 0.05
    levels = [intensity_level_db(y[:, c], fs=e.fs) for c in range(4)]
    assert np.ptp(levels) < 0.01


def test_mute_reaches_silence_within_fade_and_unmute_restores(small_bank):
    fs = small_bank.fs
    fade = int(round(0.01 * fs))
    e = make(small_bank, initial_intensity=0.8, mute_fade_s=0.01)
    ref = make(small_bank, initial_intensity=0.8, mute_fade_s=0.01)
    e.submit(SetMute(True, at_frame=2000))
    y = e.render(6000)[:, 0]
    r = ref.render(6000)[:, 0]
    np.testing.assert_array_equal(y[:2000], r[:2000])
    assert np.all(np.abs(y[2000:2000 + fade]) <= np.abs(r[2000:2000 + fade]))
    assert not y[2000 + fade:].any()
    e.submit(SetMute(False))
    y = e.render(fade + 500)[:, 0]
    assert y[fade:].any()
    np.testing.assert_array_equal(y[fade:], ref.render(fade + 500)[fade:, 0])


def test_panic_silences_and_drops_scheduled(small_bank):
    fade = int(round(0.01 * small_bank.fs))
    e = make(small_bank, initial_intensity=0.8, mute_fade_s=0.01)
    e.submit(SetKnob("intensity", 1.0, at_frame=5000))
    e.submit(Panic())
    y = e.render(8000)[:, 0]
    assert y[0] != 0 and not y[fade:].any()


def test_limiter_never_exceeds_ceiling_property(small_bank):
    rng = np.random.default_rng(42)
    ceiling = 0.5
    # ceiling_db 0 dB: the bank's peaks at knob 1 are tens of times above the limiter ceiling.
    e = make(small_bank, channels=2, ceiling_db=0.0, range_db=60.0, limiter_ceiling=ceiling)
    assert small_bank.peaks.min() > ceiling  # the limiter has work to do
    frame = 0
    peak = 0.0
    for _ in range(60):
        for _ in range(rng.integers(1, 4)):
            name = "intensity" if rng.random() < 0.5 else "balance"
            value = rng.uniform(0, 1) if name == "intensity" else rng.uniform(-3.5, 3.5)
            at = None if rng.random() < 0.5 else frame + int(rng.integers(0, 600))
            chans = None if rng.random() < 0.5 else (int(rng.integers(0, 2)),)
            e.submit(SetKnob(name, float(value), channels=chans, at_frame=at, glide_s=float(rng.choice([0, 0.001, 0.02]))))
        n = int(rng.integers(1, 700))
        y = e.render(n)
        frame += n
        peak = max(peak, float(np.abs(y).max()))
    assert peak <= ceiling
    assert peak > 0.8 * ceiling  # and it is not just silence


def test_block_by_block_equals_one_shot(small_bank):
    rng = np.random.default_rng(7)

    def commands():
        r = np.random.default_rng(11)
        out = [SetGlide(0.005, at_frame=10)]
        for k in range(40):
            name = "intensity" if k % 2 else "balance"
            value = r.uniform(0, 1) if name == "intensity" else r.uniform(-3, 3)
            out.append(SetKnob(name, float(value), at_frame=int(r.integers(0, 20000)), glide_s=float(r.choice([0, 0.003, 0.01]))))
        out.append(SetMute(True, channels=(1,), at_frame=12000))
        out.append(SetMute(False, channels=(1,), at_frame=15000))
        return out

    one = make(small_bank, channels=2)
    for c in commands():
        one.submit(c)
    full = one.render(20000)
    blocks = make(small_bank, channels=2, max_block=256)
    for c in commands():
        blocks.submit(c)
    parts, done = [], 0
    while done < 20000:
        n = min(int(rng.integers(1, 700)), 20000 - done)
        parts.append(blocks.render(n))
        done += n
    np.testing.assert_array_equal(np.concatenate(parts), full)
    assert np.abs(full).max() > 0


def test_render_into_allocates_nothing_in_steady_state(small_bank):
    e = make(small_bank, channels=8, initial_intensity=0.5, max_block=256)
    out = np.zeros((256, 8), dtype=np.float32)
    for _ in range(5):
        e.render_into(out)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        for _ in range(500):
            e.render_into(out)
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # One temporary of the block (256 x 8 float32) would be 8 KiB; Python's small int/float churn stays far below.
    assert peak - base < 2048
    assert current - base < 1024
    assert out.any()


def test_commands_from_another_thread(small_bank):
    e = make(small_bank, channels=2, glide_s=0.0)
    values = np.random.default_rng(5).uniform(0, 1, 3000)
    seqs = []

    def producer():
        for v in values:
            seqs.append(e.submit(SetKnob("intensity", float(v))))

    t = threading.Thread(target=producer)
    t.start()
    out = np.zeros((64, 2), dtype=np.float32)
    while t.is_alive():
        e.render_into(out)
    t.join()
    e.render_into(out)
    assert seqs == sorted(seqs) and len(set(seqs)) == len(values)
    assert e.applied_seq == seqs[-1]
    assert e.knob_values()[1][0] == pytest.approx(values[-1])


def test_invalid_construction_and_render(small_bank):
    with pytest.raises(ParameterError):
        Engine(small_bank, channels=0)
    with pytest.raises(ParameterError):
        Engine(small_bank, limiter_ceiling=1.5)
    with pytest.raises(ParameterError):
        make(small_bank).render(-1)
    with pytest.raises(ParameterError):
        make(small_bank).submit("intensity 1")  # type: ignore[arg-type]
