"""The follow tracker in audio mode: loudness, focus, brightness, onsets (seeded, and real sounds).

Real sounds come from Debian packages installed by ``scripts/setup.sh --test`` (never committed):
speech from ``espeak-ng``, spoken channel names from ``alsa-utils`` (/usr/share/sounds/alsa) and
desktop effects from ``sound-theme-freedesktop`` (Ogg, decoded with ``oggdec`` of ``vorbis-tools``).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from vibsynth.dsp.follow import FollowResult, Tracker, default_params, follow
from vibsynth.dsp.follow.loudness import integrated_loudness
from vibsynth.formats.recordings import read_recording

ALSA = Path("/usr/share/sounds/alsa")
FREEDESKTOP = Path("/usr/share/sounds/freedesktop/stereo")


def at_lufs(x, fs, target=-23.0):
    return x * 10 ** ((target - integrated_loudness(x, fs)) / 20)


def shake_db(r: FollowResult) -> float:
    """How hard the output shakes over the whole sound: its mean 80-200 Hz power, in dB."""
    power = np.where(r.intensity > 0, 10 ** (r.output_level_db / 10), 0.0)
    return float(10 * np.log10(power.mean() + 1e-30))


def impact(fs, seed, seconds=1.0):
    """An impact-like burst: noise with a 150 ms exponential decay, low-passed at 800 Hz."""
    t = np.arange(int(seconds * fs)) / fs
    x = np.random.default_rng(seed).standard_normal(t.size) * np.exp(-t / 0.15)
    return signal.sosfilt(signal.butter(2, 800.0, fs=fs, output="sos"), x)


@pytest.fixture(scope="module")
def speech(tmp_path_factory):
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng is not installed (scripts/setup.sh --test installs it)")
    path = tmp_path_factory.mktemp("speech") / "speech.wav"
    text = "The quick brown fox jumps over the lazy dog. Haptics should not shake for voices."
    subprocess.run(["espeak-ng", "-w", str(path), text], check=True, capture_output=True, timeout=60)
    rec = read_recording(path)
    return rec.samples, rec.fs


def desktop_sound(name, tmp_path):
    source = FREEDESKTOP / f"{name}.oga"
    if not source.exists() or shutil.which("oggdec") is None:
        pytest.skip("sound-theme-freedesktop / vorbis-tools are not installed (scripts/setup.sh --test)")
    out = tmp_path / f"{name}.wav"
    subprocess.run(["oggdec", "-Q", "-o", str(out), str(source)], check=True, capture_output=True, timeout=60)
    rec = read_recording(out)
    return rec.samples, rec.fs


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_effects_focus_holds_speech_12_db_below_an_impact_of_equal_loudness(basis, speech, seed):
    x, fs = speech
    burst = at_lufs(impact(48000.0, seed), 48000.0)
    voice = at_lufs(x, fs)
    fx = {
        f: (
            follow(voice, fs, mode="audio", focus=f, basis=basis),
            follow(burst, 48000.0, mode="audio", focus=f, basis=basis),
        )
        for f in ("effects", "all")
    }
    v, b = fx["effects"]
    assert shake_db(v) <= shake_db(b) - 12.0
    v, b = fx["all"]
    assert abs(shake_db(v) - shake_db(b)) <= 3.0


def test_real_voice_is_held_below_real_desktop_effects(basis, tmp_path):
    if not (ALSA / "Front_Left.wav").exists():
        pytest.skip("alsa-utils' sounds are not installed (scripts/setup.sh --test)")
    voice = read_recording(ALSA / "Front_Left.wav")
    crumple, fs = desktop_sound("trash-empty", tmp_path)
    v = follow(at_lufs(voice.samples, voice.fs), voice.fs, mode="audio", focus="effects", basis=basis)
    e = follow(at_lufs(crumple, fs), fs, mode="audio", focus="effects", basis=basis)
    assert shake_db(v) <= shake_db(e) - 12.0
    v_all = follow(at_lufs(voice.samples, voice.fs), voice.fs, mode="audio", focus="all", basis=basis)
    assert shake_db(v_all) > shake_db(v) + 12.0  # the focus, not the loudness, holds it down


def test_brighter_noise_has_higher_balance(basis, rng):
    fs = 48000.0
    noise = rng.standard_normal(int(1.5 * fs))
    medians = []
    for cutoff in (300.0, 500.0, 900.0, 1600.0, 3000.0, 5500.0):
        x = at_lufs(signal.sosfilt(signal.butter(4, cutoff, fs=fs, output="sos"), noise), fs)
        r = follow(x, fs, mode="audio", basis=basis)
        medians.append(float(np.median(r.balance[r.gate_open])))
    assert np.all(np.diff(medians) > 0.05)
    assert medians[0] < -2.5 and medians[-1] > 1.0  # program spans the live range


def test_onsets_mark_bursts_with_strength(basis):
    fs = 48000.0
    x = np.zeros(int(3 * fs))
    for t, amp in ((0.5, 0.05), (1.5, 0.5)):
        burst = impact(fs, int(10 * t), 0.4) * amp
        x[int(t * fs) : int(t * fs) + burst.size] += burst
    r = follow(x, fs, mode="audio", basis=basis)
    times = np.array([t for t, _ in r.onsets])
    assert times.size == 2 and np.all(np.abs(times - [0.5, 1.5]) < 0.01)
    quiet, loud = (s for _, s in r.onsets)
    assert 0 < quiet < loud <= 1
    live = Tracker(fs=fs, params=default_params("audio"), basis=basis).process(x)
    first = live.end_sample[np.flatnonzero(live.onset_strength > 0)[0]]
    assert 0 <= first - int(0.5 * fs) <= int(0.010 * fs)  # onset -> transient within 10 ms


def test_loudness_maps_range_onto_the_knob(basis, rng):
    fs = 48000.0
    x = rng.standard_normal(int(fs))
    levels = []
    for lufs in (-40.0, -30.0, -20.0):
        r = follow(at_lufs(x, fs, lufs), fs, mode="audio", basis=basis)
        levels.append(float(np.median(r.output_level_db[r.times > 0.3])))
    assert np.allclose(np.diff(levels), 10.0, atol=1.0)  # range 40 dB onto the 40 dB knob range: 1:1
    loud = follow(
        at_lufs(x, fs, -20.0), fs, mode="audio", basis=basis, params=default_params("audio").with_(gain_db=-6.0)
    )
    assert float(np.median(loud.output_level_db[loud.times > 0.3])) == pytest.approx(levels[2] - 6.0, abs=0.5)


def test_gate_closes_below_threshold(basis, rng):
    fs = 48000.0
    x = at_lufs(rng.standard_normal(int(fs)), fs, -70.0)
    r = follow(x, fs, mode="audio", basis=basis)
    assert r.silent and np.all(r.intensity == 0)


def test_bass_focus_follows_the_low_end(basis, rng):
    fs = 48000.0
    noise = rng.standard_normal(int(fs))
    low = at_lufs(signal.sosfilt(signal.butter(4, 120.0, fs=fs, output="sos"), noise), fs)
    high = at_lufs(signal.sosfilt(signal.butter(4, 2000.0, btype="high", fs=fs, output="sos"), noise), fs)
    bass = [shake_db(follow(x, fs, mode="audio", focus="bass", basis=basis)) for x in (low, high)]
    assert bass[0] > bass[1] + 20.0


def test_beat_focus_shakes_on_hits_not_on_steady_sound(basis, rng):
    fs = 48000.0
    steady = at_lufs(rng.standard_normal(int(2 * fs)), fs)
    hits = np.zeros(int(2 * fs))
    for t in (0.25, 0.75, 1.25, 1.75):
        kick = impact(fs, int(t * 100), 0.2)
        hits[int(t * fs) : int(t * fs) + kick.size] += kick
    hits = at_lufs(hits, fs)
    beat = [shake_db(follow(x, fs, mode="audio", focus="beat", basis=basis)) for x in (steady, hits)]
    assert beat[1] > beat[0] + 10.0


@pytest.mark.parametrize("bad", ["silence", "dc", "nan"])
def test_bad_audio_input(basis, rng, bad):
    fs = 48000.0
    x = {"silence": np.zeros(int(fs)), "dc": np.full(int(fs), 0.4), "nan": at_lufs(rng.standard_normal(int(fs)), fs)}[
        bad
    ]
    if bad == "nan":
        x[1000:1010] = np.nan
    r = follow(x, fs, mode="audio", basis=basis)
    if bad == "nan":
        assert r.nonfinite_samples == 10 and not r.silent
    else:
        assert r.silent and np.all(r.intensity == 0) and not r.onsets


def test_eight_channels_at_192k(basis, rng):
    fs = 192000.0
    mono = at_lufs(rng.standard_normal(int(fs)), fs)
    r = follow(np.repeat(mono[:, np.newaxis], 8, axis=1), fs, mode="audio", basis=basis)
    ref = follow(mono, fs, mode="audio", basis=basis)
    assert np.allclose(r.intensity, ref.intensity) and r.hop_s == pytest.approx(ref.hop_s)
    assert 0.002 < r.hop_s < 0.005


def test_live_changes_apply_without_reset(basis, rng):
    fs = 48000.0
    x = at_lufs(rng.standard_normal(int(fs)), fs)
    tracker = Tracker(fs=fs, params=default_params("audio"), basis=basis)
    before = tracker.process(x)
    tracker.set_params(default_params("audio").with_(gain_db=-10.0))
    after = tracker.process(x)
    assert np.median(after.intensity) == pytest.approx(np.median(before.intensity[100:]) - 10.0 / 40.0, abs=0.02)


def test_audio_frames_do_not_depend_on_block_size(basis, speech, rng):
    x, fs = speech
    reference = Tracker(fs=fs, params=default_params("audio", "effects"), basis=basis)
    whole = [reference.process(x[:2048]), reference.process(x[2048:])]
    tracker = Tracker(fs=fs, params=default_params("audio", "effects"), basis=basis)
    cuts = np.concatenate(([2048], np.sort(rng.integers(2049, x.size, 300))))
    parts = [tracker.process(p) for p in np.split(x, cuts)]
    for key in ("end_sample", "intensity", "balance", "onset_strength"):
        a = np.concatenate([getattr(p, key) for p in parts])
        b = np.concatenate([getattr(p, key) for p in whole])
        assert np.allclose(a, b, atol=1e-9), key
