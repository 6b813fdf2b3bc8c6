"""Block decimation: the same output for any blocks, the band kept, what would alias removed."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.dsp.decimate import BlockDecimator, decimation_factor
from vibsynth.errors import ParameterError


@pytest.mark.parametrize("fs, factor", [(48000, 1), (96000, 1), (176400, 2), (192000, 2), (384000, 4), (768000, 8)])
def test_factor(fs, factor):
    assert decimation_factor(fs) == factor
    assert decimation_factor(192000, 48000) == 4


def test_blocks_of_any_size_give_the_whole_signal_output():
    rng = np.random.default_rng(5)
    x = rng.standard_normal(10_007)
    whole = BlockDecimator(192000, 48000).process(x)
    d = BlockDecimator(192000, 48000)
    cuts = np.sort(rng.choice(np.arange(1, x.size), 40, replace=False))
    parts = [d.process(p) for p in np.split(x, cuts)]
    assert d.fs_out == 48000 and whole.size == -(-x.size // 4)
    assert np.allclose(np.concatenate(parts), whole, atol=1e-12)


def test_the_band_passes_and_what_would_alias_is_removed():
    fs, n = 192000, 192000
    t = np.arange(n) / fs
    d = BlockDecimator(fs, 48000)
    low = d.process(np.sin(2 * np.pi * 150 * t))[4000:]
    d = BlockDecimator(fs, 48000)
    high = d.process(np.sin(2 * np.pi * 70000 * t))[4000:]  # would fold to 22 kHz
    assert np.sqrt(np.mean(low**2)) == pytest.approx(np.sqrt(0.5), rel=1e-3)
    assert 20 * np.log10(np.sqrt(np.mean(high**2)) / np.sqrt(0.5)) < -60


def test_bad_rate():
    with pytest.raises(ParameterError):
        decimation_factor(float("nan"))
