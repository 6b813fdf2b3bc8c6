"""``open_input``: a ``--follow`` argument names a sound file, the monitor, or a device."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.engine.inputs import FileInput, SoundDeviceInput
from vibsynth.engine.monitor import MonitorInput
from vibsynth.engine.sources import open_input
from vibsynth.errors import InputError, ParameterError


def clock() -> int:
    return 0


def test_a_sound_file_is_a_file_input_whatever_its_name(tmp_path):
    rng = np.random.default_rng(5)
    wav = tmp_path / "take.wav"
    wavfile.write(wav, 24000, rng.uniform(-0.5, 0.5, (480, 3)).astype(np.float32))
    plain = tmp_path / "take"  # no sound suffix, but a file that exists
    plain.write_bytes(wav.read_bytes())
    for path in (wav, plain):
        source = open_input(str(path), fs=48000.0, frame_clock=clock, loop=True)
        assert isinstance(source, FileInput)
        assert (source.file_fs, source.channels, source.loop, source.fs) == (24000, (1, 2, 3), True, 48000.0)


def test_a_missing_file_named_like_a_sound_file_is_an_input_error_not_a_device(tmp_path):
    with pytest.raises(InputError, match="gone.flac: cannot read"):
        open_input(str(tmp_path / "gone.flac"), fs=48000.0, frame_clock=clock)


def test_monitor_is_the_monitor_input_with_the_device_options():
    source = open_input(" Monitor ", fs=44100.0, frame_clock=clock, host_api="JACK", block_size=256)
    assert isinstance(source, MonitorInput)
    assert (source.fs, source.host_api, source.block_size) == (44100.0, "JACK", 256)
    assert source.device_input is SoundDeviceInput


def test_anything_else_is_a_device_input_with_the_device_options():
    source = open_input("system:3,4", fs=48000.0, frame_clock=clock, host_api="JACK", block_size=64)
    assert isinstance(source, SoundDeviceInput)
    assert (source.spec.device, source.spec.channels, source.host_api, source.block_size) == (
        "system",
        (3, 4),
        "JACK",
        64,
    )
    with pytest.raises(ParameterError, match="channels are numbered from 1"):
        open_input("system:0", fs=48000.0, frame_clock=clock)
