"""Control layers, voices and the output tap of the compiled core, rendered block by block."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.engine.commands import CancelLayer, SetKnob, SetLayer
from vibsynth.engine.engine import TAP_MAX_FRAMES, Engine
from vibsynth.errors import ParameterError

KNOBS, SOURCES, CLIP = 0, 1, 2


def make(bank, channels=2, **kw) -> Engine:
    return Engine(bank, channels=channels, glide_s=0.0, initial_intensity=0.5, **kw)


def intensities(engine: Engine) -> list[float]:
    return [k for k, _, _ in engine.knob_values()]


# ---------------------------------------------------------------- layers
def test_a_knob_move_reaches_only_the_channels_its_layer_drives(small_bank):
    engine = make(small_bank)
    engine.submit(SetLayer(CLIP, channels=(1,)))
    engine.submit(SetKnob("intensity", 0.9))  # direct knobs: channel 0 only follows
    engine.submit(SetKnob("intensity", 0.2, layer=CLIP))  # the clip: channel 1 only follows
    engine.render(64)
    assert intensities(engine) == pytest.approx([0.9, 0.2])
    assert engine.layers() == [KNOBS, CLIP]


def test_a_layer_change_is_applied_at_its_frame_in_stream_order(small_bank):
    engine = make(small_bank, channels=1)
    engine.submit(SetLayer(SOURCES, at_frame=100))
    engine.submit(SetKnob("intensity", 0.8, layer=SOURCES, at_frame=100))
    engine.submit(SetKnob("intensity", 0.1, at_frame=50))  # knobs still drive at 50
    engine.submit(SetKnob("intensity", 0.3, at_frame=150))  # the sources drive at 150: dropped
    engine.render(75)
    assert intensities(engine) == pytest.approx([0.1])
    engine.render(125)
    assert intensities(engine) == pytest.approx([0.8])
    assert engine.layers() == [SOURCES]


def test_a_move_due_at_a_block_start_waits_for_the_switch_queued_before_it(small_bank):
    """How a clip starts: its layer switch is scheduled one block ahead, and its first move, due
    at the same frame, reaches the ring only a block later (the producer was preempted between
    the two). That move applies at the block's first sample after the switch, not before it
    (where it was dropped as a move of a layer not yet driving, and the clip was silent)."""
    engine = make(small_bank, channels=2, max_block=64)
    engine.render(64)
    start = engine.frame_position + 64
    engine.submit(SetLayer(CLIP, at_frame=start))
    engine.render(64)  # the switch waits in the schedule for the next block's first sample
    engine.submit(SetKnob("intensity", 0.9, layer=CLIP, at_frame=start))
    engine.submit(SetKnob("intensity", 0.3))  # the direct knobs, now, no longer drive
    engine.render(64)
    assert engine.layers() == [CLIP, CLIP]
    assert intensities(engine) == pytest.approx([0.9, 0.9])
    assert engine.stats.late_commands == 0 and engine.stats.pending == 0


def test_cancel_drops_a_layers_queued_moves_but_not_later_ones(small_bank):
    engine = make(small_bank, channels=2)
    engine.submit(SetLayer(CLIP))
    for k in range(1, 6):
        engine.submit(SetKnob("intensity", k / 10, layer=CLIP, at_frame=100 * k))
    engine.render(150)
    assert intensities(engine) == pytest.approx([0.1, 0.1])
    engine.submit(CancelLayer(CLIP, channels=(0,)))
    engine.submit(SetKnob("intensity", 0.95, layer=CLIP, channels=(0,), at_frame=400))
    engine.render(450)
    # channel 0: the queued 0.2..0.5 were dropped, the move sent after the cancel applied
    assert intensities(engine) == pytest.approx([0.95, 0.5])
    assert engine.stats.pending == 0


def test_panic_hands_every_channel_back_to_the_knobs(small_bank):
    from vibsynth.engine.commands import Panic

    engine = make(small_bank)
    engine.submit(SetLayer(CLIP))
    engine.render(16)
    engine.submit(Panic())
    engine.submit(SetKnob("intensity", 0.4))
    engine.render(2000)
    assert engine.layers() == [KNOBS, KNOBS]
    assert intensities(engine) == pytest.approx([0.4, 0.4])


def test_an_unknown_layer_is_refused(small_bank):
    engine = make(small_bank)
    with pytest.raises(ParameterError, match="layer"):
        engine.submit(SetLayer(7))
    with pytest.raises(ParameterError, match="layer"):
        engine.submit(SetKnob("intensity", 0.5, layer=-1))


def test_the_fast_path_shape_of_command_still_drives_knob_layer_channels(small_bank):
    """Commands pushed without a layer (the OSC fast path's C producer) are direct knob moves."""
    engine = make(small_bank)
    engine.submit(SetLayer(SOURCES, channels=(0,)))
    engine._core.push(1, 0, 0.7, float("nan"), (1 << 64) - 1, -1)
    engine.render(32)
    assert intensities(engine) == pytest.approx([0.5, 0.7])


# ---------------------------------------------------------------- voices
def test_a_voice_is_added_sample_exactly_with_faded_edges(small_bank):
    engine = Engine(small_bank, channels=2, initial_intensity=0.0)
    fs = int(engine.fs)
    rng = np.random.default_rng(4)
    samples = (0.1 * rng.standard_normal(fs // 2)).astype(np.float32)
    start = 1000
    vid = engine.play_buffer(samples, channels=[1], gain=2.0, at_frame=start)
    out = np.concatenate([engine.render(n) for n in (333, 4096, 1234, 4000, 2000)])
    assert np.all(out[:, 0] == 0.0)  # texture silent, voice on channel 1 only
    fade = round(0.005 * fs)
    played = out[start : start + samples.size, 1]
    assert np.all(out[:start, 1] == 0.0) and np.all(out[start + samples.size :, 1] == 0.0)
    middle = slice(fade, samples.size - fade)
    np.testing.assert_allclose(played[middle], 2.0 * samples[middle], rtol=1e-6, atol=1e-7)
    edge = np.minimum(np.arange(1, samples.size + 1), np.arange(samples.size, 0, -1)) / fade
    np.testing.assert_allclose(played, 2.0 * samples * np.minimum(edge, 1.0), rtol=1e-5, atol=1e-7)
    assert not engine.buffer_playing(1)
    engine.play_buffer(samples, channels=[0])  # collects the finished buffer
    assert vid not in engine._voices


def test_stop_fades_a_voice_out_and_frees_its_buffer(small_bank):
    engine = Engine(small_bank, channels=1, initial_intensity=0.0)
    engine.play_buffer(np.full(int(engine.fs), 0.5, dtype=np.float32))
    head = engine.render(2000)
    assert engine.buffer_playing(0)
    assert head[-1, 0] == pytest.approx(0.5)
    engine.stop_buffer()
    tail = engine.render(1000)
    fade = round(0.005 * engine.fs)
    assert np.all(np.diff(tail[: fade + 2, 0]) <= 1e-7)  # monotonic fade, no step
    assert np.all(tail[fade + 1 :, 0] == 0.0)
    assert not engine.buffer_playing(0)


def test_voice_gain_glides_and_the_sum_never_exceeds_the_ceiling(small_bank):
    engine = Engine(small_bank, channels=1, initial_intensity=1.0, limiter_ceiling=0.5)
    engine.play_buffer(np.ones(int(engine.fs), dtype=np.float32), gain=1.0)
    engine.render(500)
    engine.set_buffer_gain(0.0, glide_s=0.01)
    out = engine.render(2000)
    assert np.max(np.abs(out)) <= 0.5


@pytest.mark.parametrize(
    ("samples", "kw", "match"),
    [
        (np.zeros((10, 2)), {}, "mono"),
        (np.zeros(0), {}, "non-empty"),
        (np.array([0.0, np.nan]), {}, "finite"),
        (np.zeros(10), {"gain": -1.0}, "gain"),
        (np.zeros(10), {"gain": float("inf")}, "gain"),
        (np.zeros(10), {"channels": [5]}, "channels"),
    ],
)
def test_bad_voices_are_refused(small_bank, samples, kw, match):
    engine = make(small_bank)
    with pytest.raises(ParameterError, match=match):
        engine.play_buffer(samples, **kw)


# ---------------------------------------------------------------- output tap
def test_the_tap_returns_the_newest_rendered_frames(small_bank):
    engine = make(small_bank, channels=3)
    rendered = np.concatenate([engine.render(n) for n in (100, 4000, 777, 3000)])
    np.testing.assert_array_equal(engine.read_output(5000), rendered[-5000:])
    np.testing.assert_array_equal(engine.read_output(1), rendered[-1:])


def test_the_tap_pads_with_zeros_before_the_stream_and_wraps_after(small_bank):
    engine = make(small_bank, channels=1)
    first = engine.render(10)
    head = engine.read_output(20)
    assert np.all(head[:10] == 0.0)
    np.testing.assert_array_equal(head[10:], first)
    rendered = np.concatenate([engine.render(4000) for _ in range(40)])  # wraps the 65536-frame ring
    np.testing.assert_array_equal(engine.read_output(TAP_MAX_FRAMES), rendered[-TAP_MAX_FRAMES:])


def test_tap_sizes_are_checked(small_bank):
    engine = make(small_bank)
    for frames in (0, TAP_MAX_FRAMES + 1, 2.5):
        with pytest.raises(ParameterError):
            engine.read_output(frames)  # type: ignore[arg-type]


def test_the_tap_holds_engine_channels_whatever_the_device_layout(small_bank):
    engine = make(small_bank, channels=2)
    engine.set_output_map(4, [3, 1])
    buffer = np.zeros((256, 4), dtype=np.float32)
    engine._core.run_callback(buffer, 0)
    np.testing.assert_array_equal(engine.read_output(256), buffer[:, [3, 1]])
