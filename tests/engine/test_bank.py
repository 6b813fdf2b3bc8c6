"""Noise bank: iso-intensity, shared phases, balance, seamless loop, decorrelation, cache, actuator EQ."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from vibsynth.dsp.analysis import analyze
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.engine.bank import BankSpec, build_bank, cache_path, load_or_build
from vibsynth.errors import ConfigError, ParameterError


def test_shape_dtype_and_grid(small_bank):
    assert small_bank.signals.dtype == np.float32
    assert small_bank.signals.shape == (29, 32000)
    assert small_bank.signals.flags.c_contiguous
    np.testing.assert_allclose(small_bank.balances[[0, -1]], [-3.5, 3.5])
    np.testing.assert_allclose(small_bank.peaks, np.abs(small_bank.signals).max(axis=1))


def test_iso_intensity(small_bank):
    levels = [intensity_level_db(row.astype(np.float64), fs=small_bank.fs) for row in small_bank.signals]
    np.testing.assert_allclose(levels, 0.0, atol=0.01)


def test_all_levels_share_one_phase_spectrum(small_bank):
    spectra = np.fft.rfft(small_bank.signals.astype(np.float64), axis=1)
    mags = np.abs(spectra)
    strong = (mags > 1e-3 * mags.max(axis=1, keepdims=True)).all(axis=0)
    assert strong.sum() > 1000
    rel = spectra[:, strong] * np.conj(spectra[0, strong])
    np.testing.assert_allclose(np.angle(rel), 0.0, atol=1e-3)


def test_midpoint_mix_has_no_power_dip(small_bank):
    x = small_bank.signals.astype(np.float64)
    for i in (5, 14, 22):
        mix = 0.5 * (x[i] + x[i + 1])
        # A magnitude crossfade of coherent levels keeps the band level within a hair of 0 dB.
        assert abs(intensity_level_db(mix, fs=small_bank.fs)) < 0.05


def test_measured_balance_follows_grid(small_bank, basis):
    for i, b in enumerate(small_bank.balances):
        if -3.3 <= b <= 2.2:
            measured = analyze(small_bank.signals[i].astype(np.float64), fs=small_bank.fs, basis=basis).balance
            assert measured == pytest.approx(b, abs=0.03), (i, b, measured)


def test_measured_balance_is_monotonic(small_bank, basis):
    measured = [analyze(r.astype(np.float64), fs=small_bank.fs, basis=basis).balance for r in small_bank.signals]
    assert np.all(np.diff(measured) >= -1e-3)


def test_loop_seam_is_inaudible(small_bank):
    for row in small_bank.signals[[0, 14, 28]].astype(np.float64):
        steps = np.abs(np.diff(row))
        seam = abs(row[0] - row[-1])
        assert seam <= np.percentile(steps, 99.9)


def test_channel_offsets_decorrelate(small_bank):
    offsets = small_bank.channel_offsets(8)
    assert len(set(offsets.tolist())) == 8
    x = small_bank.signals[14].astype(np.float64)
    for off in offsets[1:]:
        r = np.corrcoef(x, np.roll(x, -int(off)))[0, 1]
        assert abs(r) < 0.05


def test_same_seed_same_bank_other_seed_other_bank(basis):
    spec = BankSpec(fs=8000.0, loop_seconds=0.5, levels=5, seed=7)
    a, b = build_bank(basis, spec), build_bank(basis, spec)
    np.testing.assert_array_equal(a.signals, b.signals)
    c = build_bank(basis, BankSpec(fs=8000.0, loop_seconds=0.5, levels=5, seed=8))
    assert not np.allclose(a.signals, c.signals)


def test_bad_spec_is_rejected():
    with pytest.raises(ParameterError):
        BankSpec(balance_min=1.0, balance_max=-1.0)
    with pytest.raises(ParameterError):
        BankSpec(levels=1)
    with pytest.raises(ParameterError):
        BankSpec(loop_seconds=float("nan"))


def test_cache_roundtrip_and_corrupt_file(tmp_path, basis, caplog):
    spec = BankSpec(fs=8000.0, loop_seconds=0.5, levels=5, seed=2)
    bank, origin = load_or_build(basis, spec, cache_dir=tmp_path)
    assert origin == "built"
    path = cache_path(tmp_path, spec.key(basis))
    assert path.exists()
    with np.load(path) as data:  # plain np.load-able
        np.testing.assert_array_equal(data["signals"], bank.signals)
    again, origin = load_or_build(basis, spec, cache_dir=tmp_path)
    assert origin == "cached"
    np.testing.assert_array_equal(again.signals, bank.signals)
    # corrupt: truncate
    path.write_bytes(path.read_bytes()[:1000])
    with caplog.at_level(logging.WARNING):
        rebuilt, origin = load_or_build(basis, spec, cache_dir=tmp_path)
    assert origin == "rebuilt"
    assert "rebuilding" in caplog.text
    np.testing.assert_array_equal(rebuilt.signals, bank.signals)
    assert load_or_build(basis, spec, cache_dir=tmp_path)[1] == "cached"
    # no leftover temporary files from the atomic writes
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_cache_key_covers_every_parameter(basis):
    base = BankSpec()
    variants = [
        BankSpec(fs=44100.0),
        BankSpec(loop_seconds=2.0),
        BankSpec(levels=33),
        BankSpec(balance_max=3.0),
        BankSpec(seed=2),
        BankSpec(actuator=ActuatorResponse.from_points([[100, 0], [300, 6]])),
    ]
    keys = {str(base.key(basis))} | {str(v.key(basis)) for v in variants}
    assert len(keys) == len(variants) + 1


def test_cache_disabled_and_unwritable(tmp_path, basis, caplog):
    spec = BankSpec(fs=8000.0, loop_seconds=0.5, levels=3)
    assert load_or_build(basis, spec, cache_dir="")[1] == "built"
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with caplog.at_level(logging.WARNING):
        assert load_or_build(basis, spec, cache_dir=blocker / "sub")[1] == "built"
    assert "cannot write bank cache" in caplog.text


def test_actuator_response_interpolation_and_validation():
    act = ActuatorResponse.from_points([[300, 6.0], [100, 0.0]], max_boost_db=12)
    assert act.points[0] == (100.0, 0.0)
    np.testing.assert_allclose(act.response_db([50, 100, np.sqrt(100 * 300), 300, 900]), [0, 0, 3, 6, 6])
    np.testing.assert_allclose(20 * np.log10(act.inverse_gain([100, 300])), [0, -6])
    weak = ActuatorResponse.from_points([[10, -30.0], [1000, -30.0]], max_boost_db=12)
    np.testing.assert_allclose(20 * np.log10(weak.inverse_gain([10, 500])), [12, 12])
    assert ActuatorResponse().is_flat
    for bad in ([[0, 1]], [[100, float("nan")]], [[100, 1], [100, 2]], [[100]], "x"):
        with pytest.raises(ConfigError):
            ActuatorResponse.from_points(bad)
    with pytest.raises(ConfigError):
        ActuatorResponse.from_points([], max_boost_db=-1)


def test_actuator_compensation_prequalises_and_keeps_felt_intensity(basis):
    spec = dict(fs=8000.0, loop_seconds=1.0, levels=5, seed=4)
    flat = build_bank(basis, BankSpec(**spec))
    act = ActuatorResponse.from_points([[100.0, 0.0], [400.0, 6.0]], max_boost_db=12)
    eq = build_bank(basis, BankSpec(**spec, actuator=act))
    f = np.fft.rfftfreq(flat.n_samples, 1 / flat.fs)
    pf = np.abs(np.fft.rfft(flat.signals[2].astype(np.float64))) ** 2
    pe = np.abs(np.fft.rfft(eq.signals[2].astype(np.float64))) ** 2
    band = lambda p, lo, hi: 10 * np.log10(p[(f >= lo) & (f < hi)].sum())  # noqa: E731
    # Above 400 Hz the actuator is +6 dB: the electrical drive is 6 dB lower there relative to <100 Hz.
    rel_flat = band(pf, 500, 900) - band(pf, 30, 90)
    rel_eq = band(pe, 500, 900) - band(pe, 30, 90)
    assert rel_eq - rel_flat == pytest.approx(-6.0, abs=0.2)
    # Felt signal (electrical through the actuator) keeps the 0 dB band level.
    felt = np.fft.irfft(np.fft.rfft(eq.signals[2].astype(np.float64)) * 10 ** (act.response_db(f) / 20), n=eq.n_samples)
    assert intensity_level_db(felt, fs=eq.fs) == pytest.approx(0.0, abs=0.02)
