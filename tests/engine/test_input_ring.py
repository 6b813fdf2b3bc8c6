"""The compiled input ring and its PortAudio callback, driven through the test hook (no device).

Blocks go in through ``run_callback`` (the very function PortAudio calls, GIL released) and come
out through ``read``; what comes out is compared with what went in, sample for sample.
"""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

from vibsynth.engine import _core
from vibsynth.engine.engine import Engine
from vibsynth.engine.input_ring import (
    PA_INPUT_OVERFLOW,
    PA_INPUT_UNDERFLOW,
    BlockStamp,
    InputRing,
    frame_offset,
    output_stamp,
    ring_capacity,
)
from vibsynth.errors import ParameterError


def _device_blocks(rng: np.random.Generator, total: int, device_channels: int, max_block: int) -> list[np.ndarray]:
    """Float32 device blocks (frames, device_channels) of 1..max_block frames, ``total`` frames in all."""
    data = rng.standard_normal((total, device_channels)).astype(np.float32)
    cuts = np.cumsum(rng.integers(1, max_block + 1, size=total))
    return np.split(data, cuts[cuts < total])


def test_capacity_is_a_power_of_two_holding_the_seconds():
    assert ring_capacity(48000, 1.0) == 65536
    assert ring_capacity(1000, 1.0) == 1024
    assert ring_capacity(1000, 0.01) == 1024  # at least 1024
    assert ring_capacity(44100, 2.0) == 131072
    ring = InputRing(2, 48000.0, seconds=1.0)
    assert ring.capacity == 65536 and ring.capacity >= ring.fs


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_frames_read_equal_frames_written_across_many_wraps(seed):
    rng = np.random.default_rng(seed)
    columns = [4, 0, 2]  # device inputs 5, 1 and 3 of 6
    ring = InputRing(len(columns), 1000.0, seconds=1.0)  # 1024 frames: wraps ~50 times below
    ring.set_input_map(6, columns)
    blocks = _device_blocks(rng, 50_000, 6, 300)
    got = []
    for block in blocks:
        assert ring.run_callback(block) == 0
        # the reader keeps up, in pieces of its own random size
        while ring.available:
            got.append(ring.read(int(rng.integers(1, 700))))
    sent = np.concatenate(blocks)[:, columns]
    out = np.concatenate(got)
    np.testing.assert_array_equal(out, sent)
    assert out.dtype == np.float32 and out.shape == (50_000, 3)
    assert ring.frames_written == ring.frames_read == ring.frames_captured == 50_000
    assert ring.overflows == ring.dropped_frames == 0
    assert ring.callbacks == len(blocks)


def test_a_full_ring_drops_the_newest_frames_and_counts_them():
    rng = np.random.default_rng(7)
    ring = InputRing(2, 1000.0)
    cap = ring.capacity
    blocks = _device_blocks(rng, 3 * cap + 17, 2, 200)
    sent = np.concatenate(blocks)
    for block in blocks:
        ring.run_callback(block)
    # what is kept is the oldest run, without a hole; the rest was dropped and counted
    assert ring.available == cap
    np.testing.assert_array_equal(ring.read(), sent[:cap])
    assert ring.dropped_frames == len(sent) - cap
    starts = np.cumsum([0] + [len(b) for b in blocks[:-1]])
    assert ring.overflows == sum(1 for s, b in zip(starts, blocks) if s + len(b) > cap)
    assert ring.frames_captured == len(sent) and ring.frames_written == cap
    # with room again, the next block goes in whole (after the gap the counters describe)
    more = rng.standard_normal((100, 2)).astype(np.float32)
    ring.run_callback(more)
    np.testing.assert_array_equal(ring.read(), more)
    assert ring.frames_captured - ring.dropped_frames == ring.frames_read


def test_partial_fit_keeps_the_block_head():
    ring = InputRing(1, 1000.0)
    cap = ring.capacity
    ring.run_callback(np.zeros((cap - 10, 1), np.float32))
    block = np.arange(1, 31, dtype=np.float32)[:, None]
    ring.run_callback(block)
    ring.skip(cap - 10)
    np.testing.assert_array_equal(ring.read()[:, 0], np.arange(1, 11))
    assert ring.dropped_frames == 20 and ring.overflows == 1


def test_status_flags_and_missing_input_are_counted():
    ring = InputRing(2, 48000.0)
    ring.run_callback(np.ones((64, 2), np.float32), PA_INPUT_OVERFLOW)
    ring.run_callback(np.ones((64, 2), np.float32), PA_INPUT_UNDERFLOW | PA_INPUT_OVERFLOW)
    ring.run_callback(32)  # PortAudio gave no input buffer: silence keeps the frame count
    assert ring.input_overflows == 2 and ring.input_underflows == 1 and ring.overflows == 0
    out = ring.read()
    assert out.shape == (160, 2)
    np.testing.assert_array_equal(out[:128], 1.0)
    np.testing.assert_array_equal(out[128:], 0.0)
    assert ring.frames_captured == 160


def test_stamp_records_each_block_start_and_its_times():
    ring = InputRing(1, 48000.0)
    assert ring.stamp() is None
    ring.run_callback(np.zeros((128, 1), np.float32), 0, 10.0, 10.004, 0.0)
    ring.run_callback(np.zeros((128, 1), np.float32), 0, 10.002667, 10.0067, 10.01)
    stamp = ring.stamp()
    assert isinstance(stamp, BlockStamp)
    assert stamp.frame == 128  # the block's first frame on the input's frame counter
    assert (stamp.adc_time, stamp.current_time, stamp.dac_time) == (10.002667, 10.0067, 10.01)
    assert stamp.monotonic > 0


def test_output_callback_stamps_its_blocks(small_bank):
    engine = Engine(small_bank, channels=2, max_block=64)
    assert output_stamp(engine) is None
    engine.set_output_map(2, [0, 1])
    out = np.zeros((64, 2), np.float32)
    engine._core.run_callback(out, 0)
    engine._core.run_callback(out, 0)
    stamp = output_stamp(engine)
    assert stamp is not None and stamp.frame == 64 and engine.frame_position == 128


def test_peaks_per_channel_then_reset():
    ring = InputRing(2, 48000.0)
    ring.set_input_map(3, [2, 0])
    block = np.zeros((50, 3), np.float32)
    block[10, 2] = -0.75
    block[20, 0] = 0.5
    block[30, 1] = 0.99  # not a ring channel
    ring.run_callback(block)
    assert ring.take_peaks() == [0.75, 0.5]
    assert ring.take_peaks() == [0.0, 0.0]


def test_a_real_producer_thread_and_reader_agree():
    """The callback runs on its own thread (GIL released) while the reader copies: no torn frames."""
    rng = np.random.default_rng(11)
    ring = InputRing(4, 4000.0)  # 4096 frames
    blocks = _device_blocks(rng, 100_000, 4, 128)
    got: list[np.ndarray] = []
    done = threading.Event()

    def produce() -> None:
        for block in blocks:
            while ring.capacity - ring.available < len(block):  # a reader that keeps up: never overflow
                pass
            ring.run_callback(block)
        done.set()

    thread = threading.Thread(target=produce)
    thread.start()
    while not (done.is_set() and ring.available == 0):
        got.append(ring.read(int(rng.integers(1, 3000))))
    thread.join()
    np.testing.assert_array_equal(np.concatenate(got), np.concatenate(blocks))
    assert ring.overflows == 0


def test_python_writer_uses_the_device_layout():
    ring = InputRing(1, 48000.0)
    ring.set_input_map(2, [1])
    assert ring.write(np.array([[1.0, 2.0], [3.0, 4.0]])) == 2
    np.testing.assert_array_equal(ring.read()[:, 0], [2.0, 4.0])
    with pytest.raises(ParameterError, match=r"shape \(n, 2\)"):
        ring.write(np.zeros((3, 1)))


def test_bad_arguments_are_refused():
    with pytest.raises(ParameterError):
        InputRing(0, 48000.0)
    with pytest.raises(ParameterError):
        InputRing(65, 48000.0)
    with pytest.raises(ParameterError):
        InputRing(1, float("nan"))
    ring = InputRing(2, 48000.0)
    with pytest.raises(ValueError, match="column out of range"):
        ring.set_input_map(2, [0, 2])
    with pytest.raises(ValueError, match="one device column per ring channel"):
        ring.set_input_map(4, [0])
    with pytest.raises(ValueError, match=r"float32 array \(frames, 2\)"):
        ring.run_callback(np.zeros((4, 3), np.float32))
    with pytest.raises(ParameterError):
        ring.read(-1)
    with pytest.raises(ParameterError):
        ring.skip(1.5)  # type: ignore[arg-type]
    assert ring.read(10).shape == (0, 2) and ring.skip() == 0
    assert _core.MAX_CHANNELS == 64


def test_frame_offset_puts_both_streams_on_one_clock():
    fs = 1000.0
    # output frame 500 is rendered at t = 10.000 s and heard 5 ms later; input frame 2000 was
    # captured 3 ms before its callback at t = 10.020 s (each stream's PortAudio clock differs)
    out = BlockStamp(frame=500, adc_time=0.0, current_time=1.0, dac_time=1.005, monotonic=10.000)
    inp = BlockStamp(frame=2000, adc_time=7.017, current_time=7.020, dac_time=0.0, monotonic=10.020)
    # heard at 10.005; input frame 2000 captured at 10.017: input frame 2000 - 12 = 1988 was captured then
    assert frame_offset(out, inp, fs) == pytest.approx(1988 - 500)
    assert frame_offset(out, inp, fs, device_times=False) == pytest.approx(2000 - 20 - 500)
    # any later pair of blocks of the same streams gives the same offset
    later_out = BlockStamp(frame=600, adc_time=0.0, current_time=1.1, dac_time=1.105, monotonic=10.100)
    later_in = BlockStamp(frame=2050, adc_time=7.067, current_time=7.070, dac_time=0.0, monotonic=10.070)
    assert frame_offset(later_out, later_in, fs) == pytest.approx(1988 - 500)


def test_the_input_callback_never_needs_the_gil():
    """The callback runs on a thread while this one keeps the GIL (the switch interval raised, so
    it is never handed over): a callback that asked for the GIL would wait past the deadline."""
    ring = InputRing(2, 48000.0)
    block = np.ones((128, 2), np.float32)
    ready = threading.Event()

    def call() -> None:
        ready.set()
        ring.run_callback(block, delay_s=0.2)  # lets go of the GIL, waits 0.2 s, runs the callback

    thread = threading.Thread(target=call)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        thread.start()
        ready.wait()  # this thread gets the GIL back only when the other one lets go of it
        deadline = time.monotonic() + 5.0
        while ring.callbacks == 0 and time.monotonic() < deadline:
            pass  # holds the GIL: no I/O, no sleep
        ran = ring.callbacks
    finally:
        sys.setswitchinterval(interval)
    thread.join()
    assert ran == 1
    np.testing.assert_array_equal(ring.read(), block)
