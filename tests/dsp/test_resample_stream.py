"""Block-by-block resampling equals scipy's resample_poly on the whole signal, whatever the blocks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import resample_poly

from vibsynth.dsp.resample_stream import StreamResampler
from vibsynth.errors import ParameterError


@pytest.mark.parametrize(
    ("fs_in", "fs_out", "frames"),
    [
        (44100, 48000, 30011),
        (192000, 48000, 100003),
        (48000, 48000, 1000),
        (22050, 48000, 777),
        (96000, 48000, 5),
        (8000, 48000, 1),
    ],
)
def test_blocks_of_any_size_give_the_one_shot_result(fs_in, fs_out, frames):
    rng = np.random.default_rng(frames)
    x = rng.standard_normal((frames, 2))
    r = StreamResampler(fs_in, fs_out, 2, piece=1000)
    out, i = [], 0
    while i < frames:
        n = int(rng.integers(1, 3000))
        out.append(r.process(x[i : i + n]))
        i += n
    out.append(r.flush())
    got = np.concatenate(out)
    ref = resample_poly(x, r.up, r.down, axis=0)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_memory_stays_bounded_on_a_long_stream():
    r = StreamResampler(44100, 48000, 1, piece=4096)
    block = np.zeros((1000, 1))
    for _ in range(2000):  # 45 s of input
        r.process(block)
        assert r._pending.shape[0] <= 2 * r.context + r.piece + block.shape[0]


def test_bad_rates_are_refused():
    with pytest.raises(ParameterError):
        StreamResampler(0, 48000, 1)
    with pytest.raises(ParameterError):
        StreamResampler(48000, float("nan"), 1)
    with pytest.raises(ParameterError):
        StreamResampler(48000, 44100, 0)
