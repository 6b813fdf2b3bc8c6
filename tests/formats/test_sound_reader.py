"""Sound files other than WAV (FLAC, Ogg, MP3...) read in blocks through libsndfile, and every bad file one line."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile

from vibsynth.errors import InputError
from vibsynth.formats.sound_reader import SoundFileReader, open_sound
from vibsynth.formats.wav_reader import WavReader

OGA = Path("/usr/share/sounds/freedesktop/stereo/complete.oga")


def _read_all(reader, block: int) -> np.ndarray:
    with reader:
        return np.concatenate(list(reader.blocks(block)), axis=0)


def test_flac_reads_back_what_was_written_in_any_block_size(tmp_path):
    rng = np.random.default_rng(7)
    x = np.round(rng.uniform(-0.9, 0.9, (48_123, 3)) * 2**23) / 2**23
    path = tmp_path / "scan.flac"
    soundfile.write(path, x, 96_000, subtype="PCM_24")
    reader = open_sound(path)
    assert isinstance(reader, SoundFileReader)
    assert (reader.fs, reader.channels, reader.frames) == (96_000.0, 3, 48_123)
    assert reader.sample_format == "FLAC/PCM_24" and reader.seconds == pytest.approx(48_123 / 96_000)
    for block in (997, 100_000):
        assert np.array_equal(_read_all(open_sound(path), block), x)
    with open_sound(path) as reader:  # single frames at a time too
        assert np.array_equal(np.concatenate([reader.read(1) for _ in range(50)]), x[:50])


def test_a_wav_still_goes_to_the_wav_reader_whatever_its_name(tmp_path):
    path = tmp_path / "looks-like.ogg"
    soundfile.write(path, np.zeros((100, 1)), 8000, format="WAV", subtype="PCM_16")
    with open_sound(path) as reader:
        assert isinstance(reader, WavReader) and reader.frames == 100


def test_a_real_ogg_decodes_like_vorbis_tools(tmp_path):
    if not OGA.exists() or shutil.which("oggdec") is None:
        pytest.skip("sound-theme-freedesktop / vorbis-tools are not installed (scripts/setup.sh --test)")
    wav = tmp_path / "complete.wav"
    subprocess.run(["oggdec", "-Q", "-o", str(wav), str(OGA)], check=True, capture_output=True, timeout=60)
    with WavReader(wav) as ref_reader:
        ref = ref_reader.read(ref_reader.frames)
    got = _read_all(open_sound(OGA), 4096)
    assert got.shape == ref.shape and got.shape[1] == 2
    # oggdec writes 16-bit PCM: the same decode to within its quantisation (and Vorbis float rounding)
    assert np.max(np.abs(got - ref)) < 2.0**-14
    assert np.sqrt(np.mean(ref**2)) > 0.01


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "not a sound file vibsynth reads"),
        (b"OggS" + bytes(200), "not a sound file vibsynth reads"),
        (np.random.default_rng(3).bytes(5000), "not a sound file vibsynth reads"),
    ],
)
def test_garbage_and_empty_files_are_one_clear_line(tmp_path, content, message):
    path = tmp_path / "bad.ogg"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message) as info:
        open_sound(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_a_folder_a_missing_file_and_too_many_channels_are_refused(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        open_sound(tmp_path)
    with pytest.raises(InputError, match="cannot read"):
        open_sound(tmp_path / "nope.flac")
    wide = tmp_path / "wide.w64"
    soundfile.write(wide, np.zeros((10, 65)), 48_000, format="W64", subtype="FLOAT")
    with pytest.raises(InputError, match="65 channels"):
        open_sound(wide)


def test_a_truncated_flac_ends_where_its_data_ends_or_says_it_cannot_decode(tmp_path):
    rng = np.random.default_rng(11)
    x = rng.uniform(-0.5, 0.5, (96_000, 2))
    path = tmp_path / "cut.flac"
    soundfile.write(path, x, 48_000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    try:
        with open_sound(path) as reader:
            got = np.concatenate(list(reader.blocks(8192)), axis=0)
    except InputError as exc:
        assert "cannot decode" in str(exc) and "\n" not in str(exc)
    else:
        assert 0 < got.shape[0] < x.shape[0] and reader.frames == got.shape[0]
