"""Reading recordings and PSD tables, writing WAV and basis files."""
from __future__ import annotations

import gzip

import numpy as np
import pytest
from scipy.io import wavfile

from vibsynth.errors import InputError
from vibsynth.io import load_basis, read_psd_table, read_recording, save_basis, write_wav


@pytest.mark.parametrize("dtype, scale", [(np.int16, 32768), (np.int32, 2**31), (np.float32, 1.0)])
def test_wav_formats_are_scaled_to_unit_full_scale(tmp_path, dtype, scale):
    data = np.array([0, scale // 2 if scale > 1 else 0.5, -(scale // 4 if scale > 1 else 0.25)], dtype=dtype)
    wavfile.write(tmp_path / "a.wav", 8000, data)
    rec = read_recording(tmp_path / "a.wav")
    assert rec.fs == 8000 and np.allclose(rec.samples, [0, 0.5, -0.25])


def test_multichannel_wav_channel_choice(tmp_path):
    wavfile.write(tmp_path / "s.wav", 8000, np.array([[0.1, 0.2], [0.3, 0.4]], dtype=np.float32))
    assert np.allclose(read_recording(tmp_path / "s.wav", channel=1).samples, [0.2, 0.4])
    with pytest.raises(InputError, match="channel 2 does not exist"):
        read_recording(tmp_path / "s.wav", channel=2)


def test_text_recording_with_header_and_comments(tmp_path):
    (tmp_path / "r.txt").write_text("# accelerometer\nvalue\n1.0\n-2.5\n3\n")
    rec = read_recording(tmp_path / "r.txt", fs=2800.0)
    assert np.allclose(rec.samples, [1.0, -2.5, 3.0]) and rec.fs == 2800.0
    (tmp_path / "bad.txt").write_text("1.0\nabc\n")
    with pytest.raises(InputError, match="bad.txt:2: not a number"):
        read_recording(tmp_path / "bad.txt", fs=2800.0)


def test_write_wav_pcm16_and_float(tmp_path, rng):
    x = rng.uniform(-0.9, 0.9, 100)
    write_wav(tmp_path / "f.wav", x, 8000.0)
    write_wav(tmp_path / "i.wav", x, 8000.0, sample_format="pcm16")
    assert np.allclose(read_recording(tmp_path / "f.wav").samples, x, atol=1e-7)
    assert np.allclose(read_recording(tmp_path / "i.wav").samples, x, atol=1 / 32768)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write leaves no temp file


def test_psd_table_errors(tmp_path):
    good = "texture,speed,10,20,40\nA,1,1e-3,2e-3,3e-3\n"
    with gzip.open(tmp_path / "t.csv.gz", "wt") as fh:
        fh.write(good)
    table = read_psd_table(tmp_path / "t.csv.gz")
    assert table.labels == ["A"] and table.psd.shape == (1, 3) and table.meta == [{"speed": "1"}]
    (tmp_path / "ragged.csv").write_text("texture,10,20\nA,1e-3\n")
    with pytest.raises(InputError, match="ragged.csv:2"):
        read_psd_table(tmp_path / "ragged.csv")
    (tmp_path / "neg.csv").write_text("texture,10,20\nA,1e-3,-1\n")
    with pytest.raises(InputError, match="positive"):
        read_psd_table(tmp_path / "neg.csv")


def test_basis_yaml_round_trip_and_errors(tmp_path, basis):
    save_basis(basis, tmp_path / "b.yaml")
    assert load_basis(tmp_path / "b.yaml").id == basis.id
    (tmp_path / "broken.yaml").write_text("mean_db: [1, 2\n")
    with pytest.raises(InputError, match="broken.yaml: YAML error"):
        load_basis(tmp_path / "broken.yaml")
    (tmp_path / "partial.yaml").write_text("mean_db: [1, 2]\n")
    with pytest.raises(InputError, match="partial.yaml: basis is missing the key"):
        load_basis(tmp_path / "partial.yaml")
