"""Intensity model and knob mapping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vibsynth.dsp.intensity import (
    DEFAULT_CEILING_DB,
    DEFAULT_RANGE_DB,
    gain_to_level,
    intensity_frames_db,
    intensity_level_db,
    intensity_response,
    knob_to_gain,
    knob_to_level_db,
    level_db_to_knob,
    non_stationarity_db,
)
from vibsynth.errors import ParameterError


def test_butterworth_band_edges():
    r = intensity_response([80.0, math.sqrt(80 * 200), 200.0, 20.0, 800.0])
    assert r[0] == pytest.approx(0.5) and r[1] == pytest.approx(1.0) and r[2] == pytest.approx(0.5)
    assert r[3] < 1e-3 and r[4] < 1e-3  # 4 poles: steep skirts


def test_sine_in_band_has_the_expected_level():
    fs = 8000.0
    t = np.arange(int(fs)) / fs
    x = np.sin(2 * np.pi * 126.0 * t)  # integer number of cycles, at the centre (~126.5 Hz)
    assert intensity_level_db(x, fs=fs) == pytest.approx(10 * np.log10(0.5), abs=0.01)


def test_gain_to_level_reaches_the_target(rng):
    x = rng.standard_normal(8000)
    for target in (-60.0, -20.0, 0.0):
        g = gain_to_level(x, fs=8000.0, target_db=target)
        assert intensity_level_db(g * x, fs=8000.0) == pytest.approx(target, abs=1e-9)


def test_knob_mapping_round_trip_and_silence():
    assert knob_to_level_db(0.0) == -math.inf
    assert knob_to_level_db(1.0) == DEFAULT_CEILING_DB
    assert knob_to_level_db(0.5) == DEFAULT_CEILING_DB - DEFAULT_RANGE_DB / 2
    for k in np.linspace(0.01, 1, 50):
        assert level_db_to_knob(knob_to_level_db(k)) == pytest.approx(k)
    assert level_db_to_knob(DEFAULT_CEILING_DB + 10) > 1  # reported, not clamped
    assert knob_to_gain(0.0, reference_db=0.0) == 0.0
    assert knob_to_gain(1.0, reference_db=DEFAULT_CEILING_DB) == pytest.approx(1.0)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -0.1, 1.1])
def test_knob_out_of_range_is_rejected(bad):
    with pytest.raises(ParameterError):
        knob_to_level_db(bad)


def test_non_stationarity_separates_steady_and_stepped_signals(rng):
    fs = 4000.0
    steady = rng.standard_normal(int(4 * fs))
    stepped = steady.copy()
    stepped[stepped.size // 2 :] *= 10.0  # +20 dB half-way
    assert non_stationarity_db(steady, fs=fs) < 1.5
    assert non_stationarity_db(stepped, fs=fs) == pytest.approx(10.0, abs=1.5)  # std of a 0/20 dB split
    frames = intensity_frames_db(stepped, fs=fs)
    assert frames.size == int((4.0 - 0.1) / 0.05) + 1
