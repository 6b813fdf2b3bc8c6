"""Per-channel trims: the core's CMD_TRIM (gain curve, balance offset, glided, after the layers), their derivation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.engine.bank import felt_spectra
from vibsynth.engine.commands import LAYER_NAMES, Panic, SetKnob, SetLayer
from vibsynth.engine.engine import Engine
from vibsynth.engine.trims import ChannelActuator, apply_trims, derive_trims, mean_response
from vibsynth.errors import ParameterError

FOLLOW = LAYER_NAMES.index("follow")


def make(bank, channels=2, **kw) -> Engine:
    kw.setdefault("initial_intensity", 0.5)
    return Engine(bank, channels=channels, glide_s=0.0, **kw)


def test_a_trim_gain_reaches_its_channel_only_and_glides_in(small_bank):
    plain, trimmed = make(small_bank), make(small_bank)
    plain.render(256), trimmed.render(256)
    glide = 160  # samples at 16 kHz
    trimmed.set_trim(2.0, channels=[1], glide_s=glide / small_bank.fs)
    a, b = plain.render(1024), trimmed.render(1024)
    assert np.array_equal(a[:, 0], b[:, 0])  # the other channel: bit for bit
    ratio = b[:, 1].astype(np.float64) / a[:, 1]
    want = 1.0 + np.minimum(np.arange(1, 1025), glide) / glide
    assert np.allclose(ratio, want, rtol=1e-6)
    assert trimmed.trim_values() == [(0.0, 1.0), (0.0, pytest.approx(2.0))]


def test_a_trim_sent_while_another_glides_in_waits_for_it_and_never_steps(small_bank):
    plain, trimmed = make(small_bank, channels=1), make(small_bank, channels=1)
    plain.render(256), trimmed.render(256)
    glide = 160
    seconds = glide / small_bank.fs
    trimmed.set_trim(2.0, glide_s=seconds)
    a, b = [plain.render(64)], [trimmed.render(64)]  # 64 samples into the first glide
    trimmed.set_trim(0.5, glide_s=seconds)  # superseded while it waits: the newest wins
    trimmed.set_trim(0.25, glide_s=seconds)
    for _ in range(16):  # real-time blocks: the waiting trim starts at the end of the block its predecessor ends in
        a.append(plain.render(64))
        b.append(trimmed.render(64))
    ratio = np.concatenate(b)[:, 0].astype(np.float64) / np.concatenate(a)[:, 0]
    # 1 -> 2 over the first glide (ends 160 samples in, inside the third block), 2 held to that block's end
    # (192), then 2 -> 0.25 over the next glide: linear steps of at most 1/glide and 1.75/glide, no jump
    ramp = np.arange(1, glide + 1) / glide
    want = np.concatenate([1.0 + ramp, np.full(32, 2.0), 2.0 - 1.75 * ramp, np.full(1088 - 2 * glide - 32, 0.25)])
    assert np.allclose(ratio, want, rtol=1e-6)
    assert np.abs(np.diff(ratio)).max() <= 1.75 / glide * (1 + 1e-4)  # float32 samples
    assert trimmed.trim_values() == [(0.0, pytest.approx(0.25))]


def test_a_balance_offset_plays_the_bank_where_balance_plus_offset_is(small_bank):
    offset = make(small_bank, initial_balance=0.5)
    moved = make(small_bank, initial_balance=0.75)
    offset.set_trim(1.0, 0.25, glide_s=0.0)
    assert np.array_equal(offset.render(2048), moved.render(2048))


def test_the_gain_curve_is_read_at_the_effective_bank_position(small_bank):
    levels = small_bank.levels
    curve = np.linspace(0.5, 2.0, levels)
    i = 20
    engine, plain = (
        make(small_bank, initial_balance=float(small_bank.balances[i - 2])),
        make(small_bank, initial_balance=float(small_bank.balances[i])),
    )
    step = float(small_bank.balances[i] - small_bank.balances[i - 2])
    engine.set_trim(curve, step, glide_s=0.0)
    ratio = engine.render(512).astype(np.float64) / plain.render(512)
    assert np.allclose(ratio, curve[i], rtol=1e-6)


def test_every_layer_gets_the_trim_and_panic_keeps_it(small_bank):
    engine, plain = make(small_bank), make(small_bank)
    engine.set_trim(0.5, channels=[0], glide_s=0.0)
    for e in (engine, plain):
        e.submit(SetLayer(FOLLOW, channels=(0,)))
        e.submit(SetKnob("intensity", 0.8, layer=FOLLOW))
    assert np.allclose(engine.render(512)[:, 0].astype(np.float64) / plain.render(512)[:, 0], 0.5, rtol=1e-6)
    for e in (engine, plain):
        e.submit(Panic())
        e.render(1024)
        e.submit(SetKnob("intensity", 0.6))
    assert engine.trim_values()[0] == (0.0, 0.5)
    assert np.allclose(engine.render(512)[:, 0].astype(np.float64) / plain.render(512)[:, 0], 0.5, rtol=1e-6)


def test_the_limiter_still_caps_a_trimmed_channel(small_bank):
    engine = make(small_bank, channels=1, initial_intensity=1.0, initial_balance=2.0, ceiling_db=-20.0)
    engine.set_trim(1000.0, glide_s=0.0)
    out = engine.render(small_bank.n_samples)
    assert np.abs(out).max() <= engine.limiter_ceiling


def test_an_identity_trim_restores_the_untrimmed_output(small_bank):
    engine, plain = make(small_bank), make(small_bank)
    engine.set_trim(np.linspace(0.5, 1.5, small_bank.levels), 0.3, glide_s=0.0)
    engine.render(300), plain.render(300)
    engine.set_trim(1.0, 0.0, glide_s=0.0)
    assert np.array_equal(engine.render(1024), plain.render(1024))


@pytest.mark.parametrize(
    ("args", "kw", "match"),
    [
        ((0.0,), {}, "trim gain"),
        ((math.nan,), {}, "trim gain"),
        ((np.ones(5),), {}, "trim gain"),
        ((1e9,), {}, "trim gain"),
        ((1.0, 99.0), {}, "balance offset"),
        ((1.0, math.inf), {}, "balance offset"),
        ((1.0,), {"glide_s": -1.0}, "trim glide"),
        ((1.0,), {"channels": [5]}, "trim channels"),
    ],
)
def test_bad_trims_are_refused_and_change_nothing(small_bank, args, kw, match):
    engine, plain = make(small_bank), make(small_bank)
    with pytest.raises(ParameterError, match=match):
        engine.set_trim(*args, **kw)
    assert np.array_equal(engine.render(512), plain.render(512))


# ---------------------------------------------------------------- derivation
def test_the_reference_is_the_channels_mean_response():
    a = ActuatorResponse.from_points([(10, -6), (100, 0), (1000, 6)], absolute=True)
    b = ActuatorResponse.from_points([(20, 2), (1000, 2)], absolute=True)
    mean = mean_response([a, b])
    f = np.geomspace(10, 1000, 50)
    assert np.allclose(mean.response_db(f), (a.response_db(f) + b.response_db(f)) / 2)
    assert mean.absolute and mean_response([a, a]) is a


def test_derived_trims_equalise_each_channel_in_the_bank(small_bank, basis):
    responses = [
        ActuatorResponse.from_points([(10, -12), (60, 3), (200, -2), (1000, -6)]),
        ActuatorResponse.from_points([(10, 6), (1000, 6)]),
    ]
    reference = mean_response(responses)
    channels = [ChannelActuator(f"p{i}", r) for i, r in enumerate(responses)]
    trims = derive_trims(small_bank, basis, reference, PAPER_WEIGHTING, channels, max_gain_db=40.0)
    freqs, power = felt_spectra(small_bank, reference)
    for trim, response in zip(trims, responses, strict=True):
        delta = response.response_db(freqs) - reference.response_db(freqs)
        own = PAPER_WEIGHTING.levels_from_bin_powers(freqs, power * 10 ** (delta / 10))
        ref = PAPER_WEIGHTING.levels_from_bin_powers(freqs, power)
        assert np.allclose(10 * np.log10(own / ref) + trim.gain_curve_db, 0.0)
    engine = make(small_bank)
    apply_trims(engine, trims)
    engine.render(64)
    assert [v[0] for v in engine.trim_values()] == pytest.approx([t.balance_offset for t in trims])
    # one response for every channel: nothing to trim
    same = derive_trims(small_bank, basis, responses[1], PAPER_WEIGHTING, channels[1:], max_gain_db=40.0)
    assert same[0].is_identity
