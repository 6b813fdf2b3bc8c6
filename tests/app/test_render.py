"""The one offline renderer (vibsynth.app.render) and the streaming WAV writer (vibsynth.formats.wav_stream).

* block-by-block output equals a whole-buffer render bit for bit, whatever the block size;
* cues land on their exact frame;
* a WAV written in blocks is byte-identical to ``write_wav`` of the same samples;
* a failing render leaves no file and no temporary file;
* memory stays flat (child processes, peak RSS of a long render vs a short one);
* the four callers (``render``, MIDI file, ``decode``, ``preset play -o``) produce what the
  loops they replaced produced: each old loop is reproduced here and compared bit for bit.
"""

from __future__ import annotations

import dataclasses
import io
import os
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import mido
import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.app import vbt_render
from vibsynth.app.midi_render import prepare_midi_render, render_midi_file
from vibsynth.app.render import ArrayCollector, Cue, GainSink, LoopSource, TeeSink, loop_period, render
from vibsynth.cli import main
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import SetGlide, SetKnob, SetMute
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.formats.recordings import write_wav
from vibsynth.formats.wav_stream import WavStreamWriter
from vibsynth.settings.config import default_config_data
from vibsynth.settings.typed import settings_of

ROOT = Path(__file__).resolve().parents[2]
FS = 8000.0


@pytest.fixture(scope="module")
def bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, balance_min=-2.0, balance_max=2.0, levels=9, seed=5))


def make_engine(bank, channels: int = 2) -> Engine:
    return Engine(bank, channels=channels, ceiling_db=-20.0, range_db=40.0, glide_s=0.01, max_block=512)


def random_cues(rng: np.random.Generator, frames: int, n: int = 40) -> list[Cue]:
    cues = []
    for frame in np.sort(rng.integers(0, frames, n)):
        kind = rng.integers(0, 4)
        chans = None if rng.random() < 0.5 else (int(rng.integers(0, 2)),)
        glide = None if rng.random() < 0.3 else float(rng.choice([0.0, 0.003, 0.05]))
        if kind == 0:
            cmd = SetKnob("intensity", float(rng.random()), chans, None, glide)
        elif kind == 1:
            cmd = SetKnob("balance", float(rng.uniform(-2.5, 2.5)), chans, None, glide)
        elif kind == 2:
            cmd = SetMute(bool(rng.random() < 0.5), chans)
        else:
            cmd = SetGlide(float(rng.choice([0.0, 0.02])), chans)
        cues.append(Cue(int(frame), cmd))
    return cues


def whole_buffer(bank, cues: list[Cue], frames: int) -> np.ndarray:
    """Reference: every command submitted up front with its frame, one render call."""
    engine = make_engine(bank)
    for cue in cues:
        engine.submit(dataclasses.replace(cue.action, at_frame=cue.frame))
    return engine.render(frames)


def collect(source, frames: int, **kw) -> np.ndarray:
    return render(
        source, frames, ArrayCollector(frames, source.channels, getattr(source, "dtype", np.float32)), **kw
    ).output


# --------------------------------------------------------------------------- renderer
@pytest.mark.parametrize("seed", range(4))
def test_block_by_block_equals_whole_buffer(bank, seed):
    rng = np.random.default_rng(seed)
    frames = int(rng.integers(6000, 20000))
    cues = random_cues(rng, frames)
    reference = whole_buffer(bank, cues, frames)
    assert np.abs(reference).max() > 0
    for block in (1, 7, 64, 1000, 4096, int(rng.integers(2, 3000)), frames):
        if block == 1 and seed:
            continue  # frame-by-frame once is enough (slow)
        out = collect(make_engine(bank), frames, timeline=cues, block=block)
        assert out.dtype == np.float32 and out.shape == (frames, 2)
        assert np.array_equal(out, reference), f"block {block}"


def test_cues_land_on_their_exact_frame(bank):
    frames, at = 5000, 1234
    seen = []
    cues = [
        Cue(at, SetKnob("intensity", 1.0, None, None, 0.0)),
        Cue(at + 1, lambda frame: seen.append(frame)),
        Cue(frames + 10, lambda frame: seen.append(("late", frame))),  # after the end: never applied
    ]
    for block in (100, 1000, 1234, 4096):
        seen.clear()
        out = collect(make_engine(bank), frames, timeline=cues, block=block)
        assert not out[:at].any(), block
        assert np.all(out[at] != 0), block
        assert seen == [at + 1]


def test_timeline_out_of_order_is_refused_and_nothing_is_kept(bank):
    sink = ArrayCollector(100, 2)
    with pytest.raises(ParameterError, match="out of order"):
        render(make_engine(bank), 100, sink, timeline=[Cue(50, SetMute(True)), Cue(10, SetMute(False))])
    assert sink.array is None  # aborted
    with pytest.raises(ParameterError):
        render(make_engine(bank), 0, ArrayCollector(1, 2))


def test_progress_reports_every_block_and_prints_nothing(bank, capsys):
    calls = []
    render(make_engine(bank), 2500, ArrayCollector(2500, 2), block=1000, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(1000, 2500), (2000, 2500), (2500, 2500)]
    assert capsys.readouterr() == ("", "")


def test_collector_is_bounded():
    with pytest.raises(ParameterError, match="too large to collect"):
        ArrayCollector(10**9, 2)
    ArrayCollector(10**6, 2)  # 8 MB: fine


def test_loop_source_repeats_its_period():
    period = np.random.default_rng(1).standard_normal((37, 2))
    out = collect(LoopSource(period, 1000.0), 200, block=16)
    assert out.dtype == np.float64
    assert np.array_equal(out, np.tile(period, (6, 1))[:200])


def test_loop_period_divides_the_length_when_it_can():
    assert loop_period(1000, 4000) == 1000
    assert loop_period(28_800_000, 384_000) == 384_000  # 600 s at 48 kHz: 75 periods of 8 s
    assert loop_period(480_000, 384_000) == 240_000  # 10 s: two periods of 5 s
    assert loop_period(1_000_003, 384_000) == 384_000  # a prime: no divisor, the longest period
    for n in (500_000, 576_000, 44_100 * 3600, 172_800_000):
        p = loop_period(n, 384_000)
        assert 192_000 <= p <= 384_000 and n % p == 0


# --------------------------------------------------------------------------- WAV writer
@pytest.mark.parametrize("sample_format", ["float32", "pcm16"])
@pytest.mark.parametrize("channels", [1, 3])
def test_streamed_wav_equals_write_wav(tmp_path, rng, sample_format, channels):
    x = rng.standard_normal((4321, channels)) * 0.6  # some samples beyond full scale: pcm16 clips them
    write_wav(tmp_path / "whole.wav", x if channels > 1 else x[:, 0], 44100.0, sample_format=sample_format)
    with WavStreamWriter(tmp_path / "blocks.wav", 44100.0, channels, sample_format=sample_format) as w:
        pos = 0
        while pos < len(x):
            n = int(rng.integers(1, 700))
            w.write(x[pos : pos + n] if channels > 1 else x[pos : pos + n, 0])
            pos += n
        assert w.close() == tmp_path / "blocks.wav"
    whole, blocks = (tmp_path / "whole.wav").read_bytes(), (tmp_path / "blocks.wav").read_bytes()
    assert blocks == whole
    fs, data = wavfile.read(io.BytesIO(blocks))
    assert fs == 44100 and data.shape[0] == 4321
    assert data.dtype == (np.float32 if sample_format == "float32" else np.int16)


def test_rf64_header_when_the_expected_size_needs_it(tmp_path, rng):
    x = rng.standard_normal((10, 2)).astype(np.float32)
    with WavStreamWriter(tmp_path / "big.wav", 48000, 2, frames=2**30) as w:  # 8 GiB expected: RF64
        w.write(x)
        w.close()
    raw = (tmp_path / "big.wav").read_bytes()
    assert raw[:4] == b"RF64" and raw[12:16] == b"ds64"
    riff_size, data_size, count = struct.unpack("<QQQ", raw[20:44])
    assert (riff_size, data_size, count) == (len(raw) - 8, 80, 10)
    fs, data = wavfile.read(io.BytesIO(raw))
    assert fs == 48000 and np.array_equal(data, x)


@pytest.mark.parametrize("anonymous", [True, False])
def test_error_mid_render_leaves_no_file_and_no_temp_file(tmp_path, bank, anonymous):
    target = tmp_path / "out.wav"

    def boom(done, total):
        if done >= 3000:
            raise RuntimeError("disk on fire")

    def interrupt(done, total):
        raise KeyboardInterrupt

    for error, progress in ((RuntimeError, boom), (KeyboardInterrupt, interrupt)):
        with pytest.raises(error):
            with WavStreamWriter(target, FS, 2, frames=8000, anonymous=anonymous) as w:
                render(make_engine(bank), 8000, w, block=1000, progress=progress)
        assert list(tmp_path.iterdir()) == []
    # an existing file stays untouched by a failed render, and is replaced by a good one
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with WavStreamWriter(target, FS, 2, anonymous=anonymous) as w:
            render(make_engine(bank), 8000, w, block=1000, progress=boom)
    assert target.read_bytes() == b"old" and list(tmp_path.iterdir()) == [target]
    with WavStreamWriter(target, FS, 2, anonymous=anonymous) as w:
        render(make_engine(bank), 800, w)
    assert wavfile.read(target)[1].shape == (800, 2) and list(tmp_path.iterdir()) == [target]


@pytest.mark.parametrize("anonymous", [True, False])
def test_file_mode_follows_the_umask_and_a_replaced_file_keeps_its_mode(tmp_path, anonymous):
    old = os.umask(0o027)
    try:
        with WavStreamWriter(tmp_path / "a.wav", FS, 1, anonymous=anonymous) as w:
            w.write(np.zeros(10))
            w.close()
    finally:
        os.umask(old)
    assert (tmp_path / "a.wav").stat().st_mode & 0o777 == 0o640
    (tmp_path / "a.wav").chmod(0o600)
    with WavStreamWriter(tmp_path / "a.wav", FS, 1, anonymous=anonymous) as w:
        w.write(np.zeros(20))
        w.close()
    assert (tmp_path / "a.wav").stat().st_mode & 0o777 == 0o600


def test_writer_refuses_a_missing_folder_and_a_folder(tmp_path):
    with pytest.raises(FileNotFoundError) as info:
        WavStreamWriter(tmp_path / "nope" / "x.wav", FS, 1)
    assert info.value.filename == str(tmp_path / "nope") and info.value.strerror == "folder does not exist"
    assert not (tmp_path / "nope").exists()
    with pytest.raises(IsADirectoryError):
        WavStreamWriter(tmp_path, FS, 1)
    with WavStreamWriter(tmp_path / "made" / "x.wav", FS, 1, make_folder=True) as w:
        w.write(np.zeros(4))
        w.close()
    assert (tmp_path / "made" / "x.wav").exists()


# --------------------------------------------------------------------------- memory
_RSS_CHILD = textwrap.dedent(
    """
    import resource, sys, time
    from vibsynth.cli import main
    started = time.perf_counter()
    code = main(sys.argv[1:])
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, time.perf_counter() - started, code)
    """
)


def _peak_rss_mb(*args: str) -> float:
    done = subprocess.run(
        [sys.executable, "-c", _RSS_CHILD, *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    rss_kb, _, code = done.stdout.split()[-3:]
    assert code == "0", done.stdout
    return int(rss_kb) / 1024


def test_memory_stays_flat(tmp_path):
    """A 120 s render peaks within 50 MB of a short one (before streaming: +2 GB for the texture, +90 MB for
    4 channels through the engine)."""
    cache = f"bank.cache_dir={tmp_path / 'cache'}"
    engine = ["preset", "play", "brick", "--channels", "4", "--set", cache, "-o"]
    _peak_rss_mb(*engine, str(tmp_path / "warm.wav"), "--seconds", "0.1")  # builds the bank cache
    short = _peak_rss_mb(*engine, str(tmp_path / "e10.wav"), "--seconds", "10")
    long = _peak_rss_mb(*engine, str(tmp_path / "e120.wav"), "--seconds", "120")
    assert wavfile.read(tmp_path / "e120.wav", mmap=True)[1].shape == (120 * 48000, 4)
    assert long - short < 50, (short, long)
    # the texture: both lengths repeat the same 8 s period (a 10 s one would use 5 s: a smaller synthesis)
    texture = ["render", "--balance", "0.3", "--intensity", "0.8", "--seed", "1", "-o"]
    short = _peak_rss_mb(*texture, str(tmp_path / "t16.wav"), "--seconds", "16")
    long = _peak_rss_mb(*texture, str(tmp_path / "t120.wav"), "--seconds", "120")
    assert long - short < 50, (short, long)
    for wav in tmp_path.glob("*.wav"):
        wav.unlink()  # 115 MB of output: do not keep it in pytest's temporary folders


# --------------------------------------------------------------------------- the four callers vs the old loops
def test_render_texture_matches_the_old_whole_signal_synthesis(tmp_path, basis):
    """``vibsynth render --balance`` up to the longest period: byte-identical to the former code."""
    from vibsynth.dsp.intensity import knob_to_level_db
    from vibsynth.dsp.synthesis import SpectralShaper

    for fmt, seconds, seed in (("float32", 1.0, 3), ("pcm16", 1.3, 5)):
        out = tmp_path / f"new-{fmt}.wav"
        args = ["--balance", "-0.7", "--intensity", "0.6", "--seconds", str(seconds), "--seed", str(seed)]
        assert main(["render", *args, "--rate", "8000", "--format", fmt, "-o", str(out)]) == 0
        # the former loop: one period of the whole length, written whole
        shaper = SpectralShaper(
            fs=FS, n_samples=int(round(seconds * FS)), centres=basis.centres_hz, order=basis.filter_order
        )
        weights = shaper.solve_balance(basis, -0.7, level_db=knob_to_level_db(0.6))
        signal = shaper.render(shaper.power_envelope(weights), shaper.random_phases(np.random.default_rng(seed)))
        write_wav(tmp_path / "old.wav", signal, FS, sample_format=fmt)
        assert out.read_bytes() == (tmp_path / "old.wav").read_bytes()


def test_render_long_texture_repeats_one_seamless_period(tmp_path, basis):
    out = tmp_path / "long.wav"
    assert main(["render", "--balance", "0.2", "--intensity", "0.7", "--seconds", "100", "--rate", "8000",
                 "--seed", "2", "-o", str(out)]) == 0  # fmt: skip
    _, x = wavfile.read(out)
    period = loop_period(800_000, 384_000)
    assert period == 200_000 and x.shape == (800_000,)
    np.testing.assert_array_equal(x[:period], x[period : 2 * period])
    np.testing.assert_array_equal(x[:period], x[-period:])


def _old_midi_loop(path, typed, engine, block=1024):
    """The loop of vibsynth.app.midi_render before the one renderer (copied; settings made as it makes them)."""
    from vibsynth.control.controller import Controller
    from vibsynth.control.midi.bindings import MidiSettings
    from vibsynth.control.midi.mapper import MidiMapper

    controller = Controller.for_knobs(engine, typed.knobs)
    settings = MidiSettings.from_settings(typed.midi, engine.channels, fade_ms=typed.knobs.mute_fade_ms)
    mapper = MidiMapper(controller, settings, presets=None, source="midi-file")
    events, t = [], 0.0
    for msg in mido.MidiFile(str(path)):
        t += float(msg.time)
        if not msg.is_meta:
            events.append((int(round(t * engine.fs)), msg))
    total = int(round((t + settings.release_s + 0.25) * engine.fs))
    out = np.zeros((total, engine.channels), dtype=np.float32)
    i = pos = 0
    while pos < total:
        n = min(block, total - pos)
        while i < len(events) and events[i][0] < pos + n:
            mapper.handle(events[i][1], at_frame=max(events[i][0], pos))
            i += 1
        out[pos : pos + n] = engine.render(n)
        pos += n
    return out


def _performance(path: Path) -> None:
    mid = mido.MidiFile(ticks_per_beat=480)
    track = mido.MidiTrack()
    mid.tracks.append(track)
    track.append(mido.MetaMessage("set_tempo", tempo=500000, time=0))
    for msg in (
        mido.Message("note_on", note=60, velocity=127, time=100),
        mido.Message("control_change", control=74, value=20, time=77),
        mido.Message("pitchwheel", pitch=3000, time=301),
        mido.Message("control_change", control=11, value=90, time=0),
        mido.Message("note_on", note=64, velocity=60, time=13),
        mido.Message("control_change", control=74, value=100, time=13),
        mido.Message("note_off", note=60, time=600),
        mido.Message("note_off", note=64, time=5),
    ):
        track.append(msg)
    mid.save(path)


@pytest.mark.parametrize("mode", ["gate", "continuous"])
def test_midi_file_matches_the_old_loop(tmp_path, bank, mode):
    path = tmp_path / "perf.mid"
    _performance(path)
    data = default_config_data()
    data["midi"].update(mode=mode)
    config = settings_of(data)
    old = _old_midi_loop(path, config, make_engine(bank))
    new, fs = render_midi_file(path, settings=config, engine=make_engine(bank))
    assert fs == FS and np.abs(old).max() > 0
    assert new.dtype == old.dtype and np.array_equal(new, old)
    # streamed to a WAV file: the same bytes as the old loop's write_wav
    job = prepare_midi_render(path, settings=config, engine=make_engine(bank))
    with WavStreamWriter(tmp_path / "new.wav", FS, 2, frames=job.frames) as w:
        render(job.engine, job.frames, w, timeline=job.timeline, block=333)
    write_wav(tmp_path / "old.wav", old, FS)
    assert (tmp_path / "new.wav").read_bytes() == (tmp_path / "old.wav").read_bytes()


def test_midi_file_without_a_config_uses_the_defaults(tmp_path, bank):
    path = tmp_path / "perf.mid"
    _performance(path)
    x, fs = render_midi_file(path, engine=make_engine(bank))  # config=None used to raise AttributeError
    assert fs == FS and np.abs(x).max() > 0


@pytest.fixture(scope="module")
def trajectory(basis):
    from vibsynth.dsp.codec import Quantizer, encode_trajectory
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.formats import vbt

    def part(t1, level, seed):
        spec = basis.mean_db + t1 * basis.v1
        return synthesize(spec, fs=2800.0, n_samples=8400, level_db=level, rng=np.random.default_rng(seed)).signal

    x = np.concatenate([part(10, -45, 2), part(-10, -20, 3)])
    traj = encode_trajectory(x, fs=2800.0, basis=basis, segment=False)  # one knob move per window
    return vbt.decode_bytes(vbt.encode_bytes(traj, Quantizer.fit(traj))).trajectory


def test_vbt_decode_matches_the_old_one_shot_render(tmp_path, basis, trajectory):
    from vibsynth.dsp.codec import knob_schedule

    overrides = {"bank.cache_dir": str(tmp_path), "bank.loop_seconds": 1.0, "bank.levels": 25}
    new = vbt_render.render(trajectory, basis=basis, overrides=overrides)
    assert new.n_events > 50 and new.offset_db > 0  # the limiter margin is in play
    # the former code: every knob move submitted up front (frame 0 immediate), one render call
    job = vbt_render.prepare(trajectory, basis=basis, overrides=overrides)
    engine = job.engine
    events = knob_schedule(
        trajectory, basis=basis, out_fs=job.fs, ceiling_db=engine.ceiling_db, range_db=engine.range_db,
        offset_db=job.offset_db,
    )  # fmt: skip
    for ev in events:
        at = ev.frame if ev.frame > 0 else None
        engine.submit(SetKnob("intensity", ev.intensity, at_frame=at, glide_s=ev.glide_s))
        engine.submit(SetKnob("balance", ev.balance, at_frame=at, glide_s=ev.glide_s))
    old = engine.render(job.frames)[:, 0].astype(np.float64)
    assert np.array_equal(new.signal, old)
    # decode --absolute: the gain applied block by block gives the former whole-signal product
    gain = 10 ** (job.offset_db / 20)
    job = vbt_render.prepare(trajectory, basis=basis, overrides=overrides)
    with WavStreamWriter(tmp_path / "abs.wav", job.fs, 1, frames=job.frames) as w:
        both = vbt_render.render_to(job, GainSink(TeeSink(w, ArrayCollector(job.frames, 1, np.float64)), gain))
    assert np.array_equal(both.output[1][:, 0], old * gain)
    write_wav(tmp_path / "old.wav", old * gain, job.fs)
    assert (tmp_path / "abs.wav").read_bytes() == (tmp_path / "old.wav").read_bytes()


def test_vbt_timeline_longer_than_the_engine_schedule(tmp_path, basis, trajectory):
    """Cues are fed block by block: more knob moves than schedule_capacity render fine."""
    overrides = {"bank.cache_dir": str(tmp_path), "bank.loop_seconds": 1.0, "bank.levels": 25}
    small = vbt_render.render(trajectory, basis=basis, overrides={**overrides, "knobs.schedule_capacity": 40})
    full = vbt_render.render(trajectory, basis=basis, overrides=overrides)
    assert small.n_events * 2 > 4 * 40 and np.array_equal(small.signal, full.signal)


FAST = [
    "--set", "audio.rate=8000", "--set", "bank.loop_seconds=2", "--set", "bank.levels=25",
    "--set", "bank.balance_min=-2", "--set", "bank.balance_max=2", "--set", "knobs.balance_min=-2",
    "--set", "knobs.balance_max=2", "--set", "bank.cache_dir=''", "--set", "audio.block_size=256",
]  # fmt: skip


FAST_CONFIG = {
    "audio.rate": 8000, "bank.loop_seconds": 2.0, "bank.levels": 25, "bank.balance_min": -2.0,
    "bank.balance_max": 2.0, "knobs.balance_min": -2.0, "knobs.balance_max": 2.0, "bank.cache_dir": "",
    "audio.block_size": 256,
}  # fmt: skip


@pytest.mark.parametrize("fmt, channels", [("float32", 1), ("pcm16", 2)])
def test_preset_play_to_wav_matches_the_old_loop(tmp_path, capsys, fmt, channels):
    from vibsynth.cli.preset import _preset_engine
    from vibsynth.settings.config import load_config
    from vibsynth.settings.library import load_library

    out = tmp_path / "brick.wav"
    args = ["preset", "play", "brick", "--seconds", "1.1", "--format", fmt, "--channels", str(channels)]
    assert main([*args, "-o", str(out), *FAST]) == 0
    # the former loop: engine.render(block) into a whole array, then write_wav
    config = load_config(overrides={**FAST_CONFIG, "audio.channels": channels}, user_file=False)
    engine = _preset_engine(config.settings, load_library(config.settings), "brick")
    total, block = int(round(1.1 * engine.fs)), 256
    old = np.empty((total, channels), dtype=np.float32)
    for done in range(0, total, block):
        n = min(block, total - done)
        old[done : done + n] = engine.render(n)
    write_wav(tmp_path / "old.wav", old, engine.fs, sample_format=fmt)
    assert np.abs(old).max() > 0
    assert out.read_bytes() == (tmp_path / "old.wav").read_bytes()


# --------------------------------------------------------------------------- CLI: output paths
def _bad_output_cases(tmp_path: Path) -> list[list[str]]:
    mid = tmp_path / "x.mid"
    _performance(mid)
    return [
        ["render", "--balance", "0", "--intensity", "0.5", "--seconds", "0.1", "--rate", "8000"],
        ["render", "--midi", str(mid), "--rate", "8000", "--seconds", "0.1"],
        ["preset", "play", "brick", "--seconds", "0.1", *FAST],
    ]


def test_output_in_a_missing_folder_is_refused(tmp_path, capsys):
    missing = tmp_path / "missing-dir"
    for args in _bad_output_cases(tmp_path):
        assert main([*args, "-o", str(missing / "x.wav")]) == 1, args
        err = capsys.readouterr().err
        assert err == f"vibsynth: error: {missing}: folder does not exist\n", args
        assert not missing.exists()


def test_output_naming_a_folder_is_refused(tmp_path, capsys):
    for args in _bad_output_cases(tmp_path):
        assert main([*args, "-o", str(tmp_path)]) == 1, args
        err = capsys.readouterr().err
        assert err.startswith("vibsynth: error: ") and "is a folder" in err and err.count("\n") == 1, err


def test_decode_output_errors_are_one_line(tmp_path, capsys, basis, trajectory):
    from vibsynth.dsp.codec import Quantizer
    from vibsynth.formats import vbt

    vbt.write_vbt(tmp_path / "t.vbt", trajectory, Quantizer.fit(trajectory))
    for target, message in ((tmp_path / "no" / "x.wav", "folder does not exist"), (tmp_path, "is a folder")):
        assert main(["decode", str(tmp_path / "t.vbt"), "-o", str(target)]) == 1
        err = capsys.readouterr().err
        assert err.startswith("vibsynth: error: ") and message in err and err.count("\n") == 1, err


def test_cli_render_subprocess_has_no_traceback(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "vibsynth", "render", "--balance", "0", "--intensity", "0.5", "-o", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 1 and "Traceback" not in done.stderr and done.stderr.count("\n") == 1


# --------------------------------------------------------------------------- the public API
def test_public_render_goes_through_the_one_renderer(monkeypatch):
    """vibsynth.render: the shared renderer into an array collector, same samples as the engine's own loop."""
    import vibsynth
    from vibsynth.app import api
    from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB
    from vibsynth.formats.basis_file import default_basis

    calls = []
    real = api.render_offline

    def spy(source, frames, sink, **kw):
        calls.append((type(source).__name__, frames, type(sink).__name__))
        return real(source, frames, sink, **kw)

    monkeypatch.setattr(api, "render_offline", spy)
    x = vibsynth.render(0.7, -0.4, 0.5, fs=8000.0, seed=11)
    assert calls == [("Engine", 4000, "ArrayCollector")]
    assert x.shape == (4000,) and x.dtype == np.float32 and x.flags.c_contiguous and x.flags.writeable
    seconds = api.RENDER_LOOP_SECONDS
    spec = BankSpec(fs=8000.0, loop_seconds=seconds, balance_min=-0.4, balance_max=0.6, levels=2, seed=11)
    engine = Engine(
        build_bank(default_basis(), spec), channels=1, ceiling_db=DEFAULT_CEILING_DB, range_db=DEFAULT_RANGE_DB,
        glide_s=0.0, initial_intensity=0.7, initial_balance=-0.4,
    )  # fmt: skip
    np.testing.assert_array_equal(x, engine.render(4000)[:, 0])  # the former loop, bit for bit
    with pytest.raises(ParameterError, match="too large to collect"):
        vibsynth.render(0.5, 0.0, 3600.0, fs=48000.0)  # 691 MB: refused before the bank is built
    assert len(calls) == 1
