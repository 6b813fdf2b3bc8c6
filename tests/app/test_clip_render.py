"""``render --clip``: a clip through the one offline renderer, measured, and equal to what the live player plays."""

from __future__ import annotations

import numpy as np
import pytest

from tests.control.clips.helpers import make_clip
from vibsynth.app.clip_render import TAIL_S, prepare_clip_render, render_clip
from vibsynth.cli import main
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.controller import Controller
from vibsynth.dsp.basis import to_db
from vibsynth.dsp.filterbank import band_power_frames
from vibsynth.dsp.intensity import intensity_level_db, knob_to_level_db
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.formats.basis_file import default_basis
from vibsynth.formats.recordings import read_recording
from vibsynth.settings.config import load_config

FS = 8000.0
CEILING, RANGE = -40.0, 40.0
#: plateaus (intensity, balance) with short linear moves between them, and a hold step
STAIRS = make_clip(
    [
        (0, 0.3, -1.0),
        (600, 0.3, -1.0),
        (700, 0.8, 1.5),
        (1300, 0.8, 1.5, "hold"),
        (1400, 0.55, 0.0),
        (2000, 0.55, 0.0),
    ],
    duration_ms=2000,
    name="stairs",
)


@pytest.fixture(scope="module")
def basis():
    return default_basis()


@pytest.fixture(scope="module")
def bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=2.0, levels=29, seed=3))


def engine(bank) -> Engine:
    return Engine(bank, channels=1, ceiling_db=CEILING, range_db=RANGE, glide_s=0.02)


@pytest.fixture(scope="module")
def config():
    return load_config(user_file=False).settings


def test_the_render_follows_the_keyframes_in_level_and_balance(bank, basis, config):
    x, fs = render_clip(STAIRS, settings=config, engine=engine(bank))
    assert fs == FS and x.shape == (int(2.0 * FS) + int(round((0.02 + TAIL_S) * FS)), 1)
    signal = x[:, 0].astype(np.float64)

    def balance(part: np.ndarray) -> float:
        t1 = basis.scores(to_db(band_power_frames(part, fs=FS, window_s=0.2, hop_s=0.1)))[:, 0].mean()
        return float(basis.balance_from_t1(t1))

    for (a, b), (k, bal) in [((0.1, 0.5), (0.3, -1.0)), ((0.8, 1.2), (0.8, 1.5)), ((1.5, 1.9), (0.55, 0.0))]:
        frames = slice(int(a * FS), int(b * FS))
        level = intensity_level_db(signal[frames], fs=FS)
        assert level == pytest.approx(knob_to_level_db(k, ceiling_db=CEILING, range_db=RANGE), abs=1.0)
        # the same frames of the engine held at the keyframe's knobs: the same texture
        steady = engine(bank)
        steady.submit(SetKnob("balance", bal, glide_s=0.0))
        steady.submit(SetKnob("intensity", k, glide_s=0.0))
        reference = steady.render(frames.stop)[frames, 0].astype(np.float64)
        assert level == pytest.approx(intensity_level_db(reference, fs=FS), abs=0.05)
        assert balance(signal[frames]) == pytest.approx(balance(reference), abs=0.05)
    assert balance(signal[int(0.8 * FS) : int(1.2 * FS)]) > balance(signal[int(1.5 * FS) : int(1.9 * FS)]) + 0.5
    assert np.max(np.abs(signal[-int(TAIL_S * FS) // 2 :])) == 0.0  # back to the (silent) knob state


def test_the_render_is_what_the_live_player_plays_sample_for_sample(bank, config):
    offline, _ = render_clip(STAIRS, settings=config, engine=engine(bank), gain=0.9, rate=1.5, loops=2)
    live_engine = engine(bank)
    controller = Controller(live_engine, initial_glide_s=0.02)
    player = ClipPlayer(controller, lambda name: STAIRS, start_margin_frames=0)
    player.play("stairs", gain=0.9, rate=1.5, loops=2, at_frame=0)
    blocks = []
    while live_engine.frame_position < offline.shape[0]:
        player.tick()
        blocks.append(live_engine.render(min(128, offline.shape[0] - live_engine.frame_position)))
    live = np.concatenate(blocks)
    end = int(round(2 * 2.0 / 1.5 * FS))  # the clip's own frames (the hand-back differs: a tick late, live)
    assert np.array_equal(live[:end], offline[:end])


def test_endless_loops_need_a_length_and_stream_for_as_long_as_asked(bank, config):
    with pytest.raises(ParameterError, match="loops 0 repeats the clip until stopped"):
        prepare_clip_render(STAIRS, settings=config, engine=engine(bank), loops=0)
    job = prepare_clip_render(STAIRS, settings=config, engine=engine(bank), loops=0, seconds=7.0)
    assert job.frames == int(7 * FS) and job.clip_timeline.end_frame is None


def test_render_clip_on_the_command_line_writes_the_clip(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    cfg = tmp_path / "small.yaml"
    cfg.write_text("bank:\n  levels: 9\n  loop_seconds: 1.0\n")
    out = tmp_path / "impact.wav"
    assert main(["render", "--clip", "impact", "--rate", "8000", "--config", str(cfg), "-q", "-o", str(out)]) == 0
    recording = read_recording(out)
    x = recording.samples
    assert recording.fs == 8000 and x.shape[0] == int(0.32 * 8000) + int(round(0.07 * 8000))
    assert np.max(np.abs(x[: int(0.05 * 8000)])) > 10 * np.max(np.abs(x[int(0.3 * 8000) : int(0.32 * 8000)]))
    code = main(["render", "--clip", "impakt", "-o", str(tmp_path / "x.wav")])
    assert code == 2 and "did you mean impact?" in capsys.readouterr().err
    assert not (tmp_path / "x.wav").exists()
