"""Follow offline: files streamed through the tracker into clips and renders, aligned, bounded, bad input refused."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.io import wavfile
from scipy.signal import butter, sosfilt

from vibsynth.app.clip_render import render_clip
from vibsynth.app.follow_offline import (
    MIN_SECONDS,
    AlignedFrames,
    FollowStream,
    clip_from_audio,
    offline_params,
    prepare_follow_render,
)
from vibsynth.app.render import ArrayCollector, render
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.errors import InputError
from vibsynth.formats.ahap import ahap_text, parse_ahap
from vibsynth.formats.meta_haptic import meta_haptic_text, parse_meta_haptic
from vibsynth.settings.clip_convert import ClipMapping, design_from_clip
from vibsynth.settings.clips import load_clip, save_clip
from vibsynth.settings.config import default_settings

FS = 48000


@pytest.fixture(scope="module")
def settings():
    return default_settings()


def _write(path, x, fs=FS, dtype=np.float32):
    wavfile.write(path, int(fs), np.asarray(x).astype(dtype))
    return path


def _noise(seconds, fs=FS, seed=0):
    return np.random.default_rng(seed).standard_normal(int(seconds * fs))


def _stream(path, settings, **kw):
    return FollowStream(path, settings=settings, **kw)


def _aligned(path, settings, **kw):
    with FollowStream(path, settings=settings, **kw) as stream:
        parts = list(stream.blocks())
        silent, hop = stream.silent, stream.tracker.hop
    cat = {name: np.concatenate([getattr(p, name) for p in parts]) for name in ("at", "level_db", "intensity")}
    return cat, silent, hop


def test_a_level_step_is_at_its_time_after_latency_compensation(tmp_path, settings):
    x = _noise(3.0, seed=4) * 0.01
    x[int(1.5 * FS) :] *= 10  # +20 dB at 1.5 s
    f, silent, hop = _aligned(_write(tmp_path / "step.wav", x), settings)
    assert not silent and np.all(np.diff(f["at"]) == hop) and f["at"][-1] <= x.size
    lo = np.median(f["level_db"][(f["at"] > 0.5 * FS) & (f["at"] < 1.4 * FS)])
    hi = np.median(f["level_db"][(f["at"] > 1.6 * FS) & (f["at"] < 2.9 * FS)])
    assert hi - lo == pytest.approx(20.0, abs=1.0)
    after = f["at"] > 1.0 * FS
    half = 10 * np.log10((10 ** (lo / 10) + 10 ** (hi / 10)) / 2)  # half of the power step
    first = f["at"][after][np.flatnonzero(f["level_db"][after] > half)[0]]
    assert abs(first - 1.5 * FS) <= hop  # the half-way point of the rise lands on the step


@pytest.mark.parametrize("mode", ["vibration", "audio"])
def test_a_streamed_file_gives_the_frames_follow_gives_its_samples(tmp_path, settings, mode):
    from vibsynth.dsp.follow.offline import follow
    from vibsynth.formats.basis_file import default_basis

    x = (_noise(3.0, seed=6) * np.repeat([0.01, 0.05, 0.002], FS)).astype(np.float32)
    x[int(2.2 * FS)] += 0.5
    path = _write(tmp_path / "same.wav", x)
    knobs = settings.knobs
    ref = follow(
        x.astype(np.float64),
        FS,
        params=offline_params(mode),
        basis=default_basis(),
        ceiling_db=knobs.ceiling_db,
        range_db=knobs.range_db,
        balance_limits=(knobs.balance_min, knobs.balance_max),
    )
    with FollowStream(path, settings=settings, mode=mode) as stream:
        got = AlignedFrames.concat(list(stream.blocks()))
    assert np.array_equal(got.at / FS, ref.times)
    # equal up to the audio analysis' own dependence on where blocks start (~1e-3 in the first 50 ms)
    assert np.allclose(got.intensity, ref.intensity, atol=1e-4) and np.allclose(got.balance, ref.balance, atol=0.01)
    assert np.allclose(got.intensity[20:], ref.intensity[20:], atol=1e-6)


@pytest.mark.parametrize("mode", ["vibration", "audio"])
def test_impulses_become_transients_at_their_times(tmp_path, settings, mode):
    y = _noise(4.0, seed=9) * 0.001
    times = [0.5, 1.25, 2.0, 2.9, 3.5]
    for t in times:
        y[int(t * FS)] += 0.9
    made = clip_from_audio(_stream(_write(tmp_path / "imp.wav", y), settings, mode=mode), name="imp", settings=settings)
    got = [tr.t_ms for tr in made.clip.transients]
    assert len(got) == len(times)
    hop_ms = 1000 * FollowStream(tmp_path / "imp.wav", settings=settings, mode=mode).tracker.hop / FS
    assert np.max(np.abs(np.array(got) - 1000 * np.array(times))) <= hop_ms + 1.0
    assert all(tr.intensity > made.clip.value_at(tr.t_ms)[0] for tr in made.clip.transients)  # each lifts the curve


def test_stereo_and_8_channel_192k_follow_like_mono(tmp_path, settings):
    x = _noise(2.0, seed=1) * 0.05
    x[FS:] *= 0.3
    mono = clip_from_audio(_stream(_write(tmp_path / "m.wav", x), settings), name="m", settings=settings)
    stereo = clip_from_audio(
        _stream(_write(tmp_path / "s.wav", np.stack([x, x], 1)), settings), name="s", settings=settings
    )
    assert stereo.clip.keyframes == mono.clip.keyframes and stereo.clip.transients == mono.clip.transients
    # the same sound at 192 kHz on 8 channels (equal copies: their mean is the sound)
    from scipy.signal import resample_poly

    hi = resample_poly(x, 4, 1)
    wide = clip_from_audio(
        _stream(_write(tmp_path / "w.wav", np.tile(hi[:, None], (1, 8)), fs=4 * FS), settings),
        name="w",
        settings=settings,
    )
    t = np.arange(100, 1900, 10.0)
    a, b = mono.clip.values_at(t), wide.clip.values_at(t)
    assert np.median(np.abs(a[:, 0] - b[:, 0])) * settings.knobs.range_db < 1.0  # within 1 dB typically
    assert wide.clip.duration_ms == pytest.approx(2000.0)


def test_simplification_is_bounded_and_states_its_real_error(tmp_path, settings):
    path = _write(tmp_path / "n.wav", _noise(6.0, seed=2) * np.linspace(0.001, 0.1, int(6 * FS)))
    fine = clip_from_audio(_stream(path, settings), name="n", settings=settings, tolerance_db=1.0)
    short = clip_from_audio(_stream(path, settings), name="n", settings=settings, max_keyframes=20)
    assert fine.within and fine.max_error_db <= 1.0 + 1e-9 and fine.max_error_balance <= 0.1 + 1e-9
    assert len(short.clip.keyframes) == 20 and not short.within and short.max_error_db > fine.max_error_db
    assert f"max error {short.max_error_db:.2f} dB" in short.clip.description
    with FollowStream(path, settings=settings) as stream:
        parts = list(stream.blocks())
    at = np.concatenate([p.at for p in parts]) / FS * 1000
    tracked = np.concatenate([p.intensity for p in parts])
    err = np.max(np.abs(short.clip.values_at(at)[:, 0] - tracked)) * settings.knobs.range_db
    assert err == pytest.approx(short.max_error_db, rel=1e-6)


def test_the_clip_plays_renders_and_exports(tmp_path, settings):
    y = _noise(1.5, seed=3) * 0.05
    y[int(0.7 * FS)] += 0.9
    made = clip_from_audio(_stream(_write(tmp_path / "p.wav", y), settings), name="p", settings=settings)
    saved = load_clip(save_clip(made.clip, tmp_path / "p.yaml"))
    assert saved == made.clip
    out, fs = render_clip(saved, settings=settings)
    sos = butter(2, (80, 200), btype="bandpass", fs=fs, output="sos")
    assert fs == FS and np.sqrt(np.mean(sosfilt(sos, out[: int(1.4 * fs), 0]) ** 2)) > 0
    mapping = ClipMapping()
    design = design_from_clip(saved, mapping)
    for back in (parse_ahap(ahap_text(design)), parse_meta_haptic(meta_haptic_text(design))):
        assert len(back.taps) == len(saved.transients) and back.duration_s == pytest.approx(1.5)


def test_render_follows_the_input_level_and_keeps_its_length(tmp_path, settings):
    x = _noise(3.0, seed=5) * 0.02
    x[int(1.5 * FS) :] *= 0.1  # -20 dB at 1.5 s
    job = prepare_follow_render(_stream(_write(tmp_path / "r.wav", x), settings), settings=settings)
    with job.stream:
        result = render(job.engine, job.frames, ArrayCollector(job.frames, 1), timeline=job.timeline)
    y = result.output[:, 0].astype(np.float64)
    assert y.size == x.size
    for a, b in ((0.3, 1.4), (1.6, 2.9)):  # the output's 80-200 Hz level is the input's
        s = slice(int(a * FS), int(b * FS))
        assert intensity_level_db(y[s], fs=FS) == pytest.approx(intensity_level_db(x[s], fs=FS), abs=1.5)


def test_silence_says_so_and_plays_silence(tmp_path, settings):
    path = _write(tmp_path / "z.wav", np.zeros(FS))
    made = clip_from_audio(_stream(path, settings), name="z", settings=settings)
    assert made.silent and "silent input" in made.clip.description
    assert all(k.intensity == 0 for k in made.clip.keyframes) and not made.clip.transients
    job = prepare_follow_render(_stream(path, settings), settings=settings)
    with job.stream:
        result = render(job.engine, job.frames, ArrayCollector(job.frames, 1), timeline=job.timeline)
    assert result.peak == 0.0 and job.stream.silent


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: _write(p, np.zeros(1)), "1 sample (0.021 ms) is too short to follow"),
        (lambda p: _write(p, np.r_[np.zeros(FS), np.nan, np.zeros(10)]), "NaN or infinite sample at 1.000 s"),
        (lambda p: p.write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunkjunk"), "not a readable WAV file"),
        (lambda p: p.write_bytes(b"not a wav at all"), "not a sound file vibsynth reads"),
    ],
)
def test_bad_input_is_one_line(tmp_path, settings, make, message):
    path = tmp_path / "bad.wav"
    make(path)
    with pytest.raises(InputError) as info:
        clip_from_audio(_stream(path, settings), name="bad", settings=settings)
    assert message in str(info.value) and "\n" not in str(info.value)
    assert MIN_SECONDS > 0


def test_longer_than_a_clip_is_refused_before_tracking(tmp_path, settings):
    from vibsynth.formats.wav_stream import WavStreamWriter

    path = tmp_path / "long.wav"
    with WavStreamWriter(path, 4000, 1, sample_format="pcm16") as w:  # 11 min at 4 kHz: cheap to write
        for _ in range(11):
            w.write(np.zeros(240_000))
        w.close()
    with pytest.raises(InputError, match="11.0 min is longer than a clip holds"):
        clip_from_audio(_stream(path, settings), name="long", settings=settings)
