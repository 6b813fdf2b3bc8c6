"""Engine: levels, glide, crossfade, limiter, mute, scheduling, block invariance, no allocation, threads."""

from __future__ import annotations

import threading
import tracemalloc

import numpy as np
import pytest

from vibsynth.dsp.intensity import intensity_level_db, knob_to_level_db
from vibsynth.engine._core import DRAIN_MAX
from vibsynth.engine.commands import Panic, SetGlide, SetKnob, SetMute
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError, ScheduleFullError


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
    assert intensity_level_db(x, fs=e.fs) == pytest.approx(
        knob_to_level_db(knob, ceiling_db=-40, range_db=40), abs=0.05
    )


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
    assert np.all(np.abs(y[2000 : 2000 + fade]) <= np.abs(r[2000 : 2000 + fade]))
    assert not y[2000 + fade :].any()
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
            e.submit(
                SetKnob(name, float(value), channels=chans, at_frame=at, glide_s=float(rng.choice([0, 0.001, 0.02])))
            )
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
            out.append(
                SetKnob(
                    name, float(value), at_frame=int(r.integers(0, 20000)), glide_s=float(r.choice([0, 0.003, 0.01]))
                )
            )
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
    # At most DRAIN_MAX commands leave the ring per block: the backlog drains over a bounded
    # number of further blocks, never all at once.
    for _ in range(-(-len(values) // DRAIN_MAX)):
        before = e.applied_seq
        e.render_into(out)
        assert e.applied_seq - before <= DRAIN_MAX
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


def test_schedule_cap_refuses_and_counts_and_frees_when_fired(small_bank):
    e = make(small_bank, schedule_capacity=100)
    for k in range(100):
        e.submit(SetKnob("intensity", 0.5, at_frame=1000 + k))
    with pytest.raises(ScheduleFullError):
        e.submit(SetKnob("intensity", 0.9, at_frame=5000))
    assert e.stats.schedule_full == 1 and e.stats.pending == 100
    e.submit(SetKnob("intensity", 0.1))  # immediate commands are not capped
    e.render(2000)
    assert e.stats.pending == 0
    e.submit(SetKnob("intensity", 0.9, at_frame=5000))  # room again
    assert e.stats.pending == 1


def test_panic_frees_the_schedule(small_bank):
    e = make(small_bank, schedule_capacity=10)
    for k in range(10):
        e.submit(SetKnob("intensity", 0.5, at_frame=10_000 + k))
    e.render(64)
    e.submit(Panic())
    e.render(64)
    assert e.stats.pending == 0


def test_out_of_order_schedule_applies_in_time_order(small_bank):
    e = make(small_bank, glide_s=0.0)
    rng = np.random.default_rng(11)
    frames = rng.permutation(np.arange(100, 5100, 50))
    for f in frames:  # arrive in random order, each sets intensity to a value encoding its frame
        e.submit(SetKnob("intensity", float(f) / 10_000, at_frame=int(f)))
    e.render(6000)
    assert e.knob_values()[0][0] == pytest.approx(5050 / 10_000)


def test_block_cost_is_bounded_with_a_full_schedule(small_bank):
    """100,000 timetagged commands refused past the cap, and the 10,000 accepted add only
    O(log n) per block: the block that holds them renders about as fast as a quiet one."""
    import time

    e = make(small_bank, glide_s=0.0)
    out = np.zeros((128, 1), dtype=np.float32)

    def block_time(engine):
        t0 = time.perf_counter()
        for _ in range(50):
            engine.render_into(out)
        return time.perf_counter() - t0

    quiet = min(block_time(e) for _ in range(5))
    refused = 0
    for k in range(100_000):
        try:
            e.submit(SetKnob("intensity", 0.5, at_frame=10**9 + k))
        except ScheduleFullError:
            refused += 1
    assert refused == 100_000 - e.schedule_capacity
    for _ in range(20):  # the ring hands them over, DRAIN_MAX per block
        e.render_into(out)
    assert e.stats.pending == e.schedule_capacity
    loaded = min(block_time(e) for _ in range(5))
    assert loaded < 3 * quiet + 1e-3  # a heap: no O(n) insert or pop(0) per block


def test_matches_the_reference_mixer(small_bank):
    """The compiled kernel computes what the engine's equations say, sample by sample."""
    e = make(small_bank, channels=1, glide_s=0.0, initial_intensity=0.6, initial_balance=0.7)
    y = e.render(500)[:, 0].astype(np.float64)
    bank = small_bank
    lo, hi = bank.balances[0], bank.balances[-1]
    pos = (0.7 - lo) * (bank.levels - 1) / (hi - lo)
    i = int(np.floor(pos))
    f = pos - i
    gain_db = e.ceiling_db - e.range_db * (1 - 0.6)
    bound = (1 - f) * bank.peaks[i] + f * bank.peaks[i + 1]
    gain = min(10 ** (gain_db / 20), e.limiter_ceiling / bound)
    n = np.arange(500)
    expected = gain * ((1 - f) * bank.signals[i, n] + f * bank.signals[i + 1, n])
    np.testing.assert_allclose(y, expected, rtol=1e-5, atol=1e-9)
