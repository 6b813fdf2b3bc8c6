"""The streaming WAV reader: every encoding against scipy's reading, block independence, and each bad file."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.errors import InputError
from vibsynth.formats.recordings import read_recording
from vibsynth.formats.wav_reader import WavReader


def _pcm24(path, fs, x):
    """A 24-bit PCM WAV (scipy writes no 24-bit): header by hand, samples little-endian."""
    q = np.clip(np.round(x * 2**23), -(2**23), 2**23 - 1).astype("<i4")
    raw = np.stack([(q >> s) & 0xFF for s in (0, 8, 16)], axis=-1).astype(np.uint8).tobytes()
    ch = x.shape[1]
    fmt = struct.pack("<HHIIHH", 1, ch, fs, fs * 3 * ch, 3 * ch, 24)
    body = b"WAVEfmt " + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", len(raw)) + raw
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


@pytest.mark.parametrize("dtype", ["uint8", "int16", "int32", "float32", "float64", "pcm24"])
def test_each_encoding_reads_as_scipy_reads_it_in_any_block_size(tmp_path, dtype):
    rng = np.random.default_rng(3)
    x = rng.uniform(-0.9, 0.9, (1001, 3))
    path = tmp_path / "x.wav"
    if dtype == "pcm24":
        _pcm24(path, 44100, x)
    else:
        scale = {"uint8": 127, "int16": 2**15 - 1, "int32": 2**31 - 1}.get(dtype)
        data = x if scale is None else np.round(x * scale)
        if dtype == "uint8":
            data = data + 128
        wavfile.write(path, 44100, data.astype(dtype))
    with WavReader(path) as r:
        assert (r.fs, r.channels, r.frames) == (44100.0, 3, 1001)
        got = np.concatenate(list(r.blocks(97)))
    for c in range(3):
        assert np.array_equal(got[:, c], read_recording(path, channel=c).samples) or dtype == "pcm24"
    assert np.max(np.abs(got - x)) < {"uint8": 0.02, "int16": 1e-4}.get(dtype, 1e-6)


def _header_only(path, data_bytes, *, channels=1, fs=48000, bits=16, tag=1, extra=b""):
    fmt = struct.pack("<HHIIHH", tag, channels, fs, fs * channels * bits // 8, channels * bits // 8, bits)
    body = b"WAVEfmt " + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", data_bytes) + extra
    path.write_bytes(b"RIFF" + struct.pack("<I", 36 + len(extra)) + body)


def test_bad_files_get_one_line_each(tmp_path):
    cases = {}
    p = tmp_path / "huge.wav"
    _header_only(p, 0xFFFFFF00, extra=b"\0" * 100)
    cases[p] = "header claims 4.3 GB of samples (44,739 s) but the file holds 100 bytes: truncated or corrupt"
    p = tmp_path / "garbage.wav"
    p.write_bytes(np.random.default_rng(1).bytes(500))
    cases[p] = "not a WAV file (no RIFF/WAVE header)"
    p = tmp_path / "empty.wav"
    p.write_bytes(b"")
    cases[p] = "not a WAV file"
    p = tmp_path / "nodata.wav"
    _header_only(p, 0)
    cases[p] = "contains no samples"
    p = tmp_path / "cut.wav"
    wavfile.write(p, 48000, np.zeros(1000, np.int16))
    p.write_bytes(p.read_bytes()[:30])
    cases[p] = "truncated 'fmt ' chunk"
    p = tmp_path / "adpcm.wav"
    _header_only(p, 2, tag=2, extra=b"\0\0")
    cases[p] = "format tag 0x0002 is not supported"
    p = tmp_path / "many.wav"
    _header_only(p, 200, channels=100, extra=b"\0" * 200)
    cases[p] = "has 100 channels (taken: 1..64)"
    p = tmp_path / "slow.wav"
    _header_only(p, 2, fs=8, extra=b"\0\0")
    cases[p] = "sample rate 8 Hz is outside"
    p = tmp_path / "nan.wav"
    x = np.zeros(48000, np.float32)
    x[36000] = np.nan
    wavfile.write(p, 48000, x)
    cases[p] = "NaN or infinite sample at 0.750 s (frame 36,000)"
    cases[tmp_path / "missing.wav"] = "cannot read (No such file or directory)"
    cases[tmp_path] = "is a folder"
    for path, message in cases.items():
        with pytest.raises(InputError) as info:
            with WavReader(path) as r:
                for _ in r.blocks(4096):
                    pass
        assert str(info.value).startswith(f"{path}: ") and message in str(info.value), str(info.value)
        assert "\n" not in str(info.value)


def test_rf64_takes_its_sizes_from_the_ds64_chunk(tmp_path):
    x = np.arange(-50, 50, dtype=np.float32) / 64
    raw = x.astype("<f4").tobytes()
    fmt = struct.pack("<HHIIHH", 3, 1, 48000, 48000 * 4, 4, 32)
    ds64 = b"ds64" + struct.pack("<IQQQI", 28, 0, len(raw), 100, 0)
    body = b"WAVE" + ds64 + b"fmt " + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", 0xFFFFFFFF) + raw
    path = tmp_path / "big.wav"
    path.write_bytes(b"RF64" + struct.pack("<I", 0xFFFFFFFF) + body)
    with WavReader(path) as r:
        assert r.frames == 100 and r.sample_format == "float32"
        assert np.array_equal(r.read(1000)[:, 0], x.astype(np.float64))


def test_an_rf64_header_claiming_terabytes_is_one_line(tmp_path):
    fmt = struct.pack("<HHIIHH", 1, 8, 192000, 192000 * 16, 16, 16)
    ds64 = b"ds64" + struct.pack("<IQQQI", 28, 0, 2 * 10**12, 10**11, 0)
    body = b"WAVE" + ds64 + b"fmt " + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", 0xFFFFFFFF)
    path = tmp_path / "huge.wav"
    path.write_bytes(b"RF64" + struct.pack("<I", 0xFFFFFFFF) + body + b"\0" * 64)
    with pytest.raises(InputError) as info:
        WavReader(path)
    assert str(info.value) == (
        f"{path}: the header claims 2.0 TB of samples (651,042 s) but the file holds 64 bytes: truncated or corrupt"
    )
