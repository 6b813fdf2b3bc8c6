"""render --follow streams: the peak memory of a long input is that of a short one (tracemalloc).

The suite compares 2 and 12 minutes (six times longer: any growth with the length shows);
``VIBSYNTH_FOLLOW_MEMORY_MINUTES=10,60`` runs the hour (a few minutes of tracking), as
``benchmarks/bench_follow_offline.py --long`` does for peak RSS.
"""

from __future__ import annotations

import os
import tracemalloc

import numpy as np

from vibsynth.app.follow_offline import FollowStream, prepare_follow_render
from vibsynth.app.render import render
from vibsynth.dsp.follow.params import default_params
from vibsynth.formats.wav_stream import WavStreamWriter
from vibsynth.settings.config import load_config

RATE = 8000  # input and output: keeps long files cheap to write, track and render
MINUTES = tuple(int(m) for m in os.environ.get("VIBSYNTH_FOLLOW_MEMORY_MINUTES", "2,12").split(","))


def _long_input(path, minutes):
    """Noise with a level step every second, written a minute at a time (never held whole)."""
    rng = np.random.default_rng(minutes)
    with WavStreamWriter(path, RATE, 2, sample_format="pcm16", frames=minutes * 60 * RATE) as w:
        for _ in range(minutes):
            gains = np.repeat(0.05 * 10 ** (-rng.uniform(0, 20, 60) / 20), RATE)
            w.write(rng.standard_normal((60 * RATE, 2)) * gains[:, None])
        w.close()


def _peak_bytes(src, out, settings):
    params = default_params("audio").with_(hop_ms=50.0)
    tracemalloc.start()
    try:
        job = prepare_follow_render(FollowStream(src, settings=settings, params=params), settings=settings)
        with job.stream, WavStreamWriter(out, job.fs, 1, sample_format="pcm16", frames=job.frames) as wav:
            result = render(job.engine, job.frames, wav, timeline=job.timeline, block=4096)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, result


def test_a_long_input_renders_in_the_memory_of_a_short_one(tmp_path):
    overrides = {"audio": {"rate": RATE}, "bank": {"levels": 9, "loop_seconds": 1.0, "cache_dir": str(tmp_path)}}
    settings = load_config(overrides=overrides, user_file=False).settings
    peaks = {}
    short, long = MINUTES
    for minutes in (short, long):
        src, out = tmp_path / f"in{minutes}.wav", tmp_path / f"out{minutes}.wav"
        _long_input(src, minutes)
        peaks[minutes], result = _peak_bytes(src, out, settings)
        assert result.frames == minutes * 60 * RATE and out.stat().st_size > minutes * 60 * RATE * 2
        src.unlink()
        out.unlink()
    whole_input = long * 60 * RATE * 2 * 8  # the long input as float64
    assert peaks[long] < 1.25 * peaks[short] + (2 << 20), peaks  # flat: no growth with the length
    assert peaks[long] < whole_input / 5, peaks  # and nowhere near holding the input
    print(f"tracemalloc peak: {short} min {peaks[short] / 2**20:.1f} MiB, {long} min {peaks[long] / 2**20:.1f} MiB")
