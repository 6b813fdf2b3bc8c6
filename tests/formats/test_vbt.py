"""The .vbt format: round trip, size, engine decoding, and fuzzing (truncation, byte flips, versions)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from vibsynth.app import vbt_render
from vibsynth.dsp.codec import Quantizer, encode_trajectory, quality
from vibsynth.dsp.synthesis import synthesize
from vibsynth.errors import CodecError, InputError
from vibsynth.formats import vbt

FS = 2800.0


def noise(basis, t1, level, seed, seconds):
    spec = basis.mean_db + t1 * basis.v1
    return synthesize(spec, fs=FS, n_samples=int(seconds * FS), level_db=level, rng=np.random.default_rng(seed)).signal


@pytest.fixture(scope="module")
def stationary(basis):
    x = noise(basis, 15.0, -40.0, 1, 10.0)
    traj = encode_trajectory(x, fs=FS, basis=basis)
    return x, traj, Quantizer.fit(traj)


@pytest.fixture(scope="module")
def step(basis):
    x = np.concatenate([noise(basis, 0.0, -45.0, 2, 5.0), noise(basis, 0.0, -35.0, 3, 5.0)])
    traj = encode_trajectory(x, fs=FS, basis=basis)
    return x, traj, Quantizer.fit(traj)


@pytest.fixture(scope="module")
def engine_overrides(tmp_path_factory):
    return {"bank.cache_dir": str(tmp_path_factory.mktemp("bank"))}


def test_round_trip_is_exact_after_quantisation(stationary, step):
    for _, traj, q in (stationary, step):
        data = vbt.encode_bytes(traj, q)
        dec = vbt.decode_bytes(data)
        ref = q.quantize(traj)
        assert np.array_equal(dec.trajectory.level_db, ref.level_db) and np.array_equal(dec.trajectory.t1, ref.t1)
        assert (dec.trajectory.fs, dec.trajectory.n_samples, dec.trajectory.window, dec.trajectory.hop) == (
            traj.fs,
            traj.n_samples,
            traj.window,
            traj.hop,
        )
        assert dec.trajectory.basis_id == traj.basis_id


def test_stationary_recording_is_a_few_bytes_per_second(stationary):
    _, traj, q = stationary
    data = vbt.encode_bytes(traj, q)
    assert len(data) / traj.duration_s < 10.0  # 10 s -> one segment: header + 4 bytes + CRC
    assert len(data) == vbt.HEADER.size + 4 + 4


def test_per_window_mode_uses_plain_records(basis, stationary):
    x, _, _ = stationary
    traj = encode_trajectory(x, fs=FS, basis=basis, segment=False)
    for bits in (3, 8, 12):
        q = Quantizer.fit(traj, bits=bits)
        dec = vbt.decode_bytes(vbt.encode_bytes(traj, q))
        assert not dec.run_length and dec.n_records == traj.n_frames
        assert dec.size_bytes == vbt.HEADER.size + (2 * bits * traj.n_frames + 7) // 8 + 4
        assert np.allclose(dec.trajectory.level_db, traj.level_db, atol=q.level_step / 2 + 1e-6)


def test_stationary_decodes_within_1_db_band_error(basis, stationary, engine_overrides):
    x, traj, q = stationary
    dec = vbt.decode_bytes(vbt.encode_bytes(traj, q))
    out = vbt_render.render(dec.trajectory, basis=basis, overrides=engine_overrides)
    assert out.signal.shape == x.shape and out.fs == FS
    qual = quality(x, out.signal, fs=FS, basis=basis, offset_db=out.offset_db)
    assert qual.band_error_rms_db < 1.0 and qual.band_error_max_db < 1.5
    assert abs(qual.level_error_db) < 0.5
    assert qual.dissimilarity < 1.0


def test_step_decodes_with_the_step_in_the_right_window(basis, step, engine_overrides):
    from vibsynth.dsp.intensity import intensity_frames_db

    x, traj, q = step
    out = vbt_render.render(
        vbt.decode_bytes(vbt.encode_bytes(traj, q)).trajectory, basis=basis, overrides=engine_overrides
    )
    a = intensity_frames_db(x, fs=FS)
    b = intensity_frames_db(out.signal, fs=FS) + out.offset_db
    mid = (-45.0 + -35.0) / 2
    # First window above the midpoint, in the original and in the decoded signal.
    first = lambda lv: int(np.argmax(np.convolve(lv > mid, np.ones(3), "valid") == 3))  # noqa: E731
    assert abs(first(a) - first(b)) <= 1
    assert np.median(b[:80]) == pytest.approx(-45.0, abs=1.0) and np.median(b[-80:]) == pytest.approx(-35.0, abs=1.0)
    qual = quality(x, out.signal, fs=FS, basis=basis, offset_db=out.offset_db)
    assert abs(qual.non_stationarity_decoded_db - qual.non_stationarity_original_db) < 0.5


def test_every_truncation_is_a_clear_error(step):
    _, traj, q = step
    data = vbt.encode_bytes(traj, q)
    for n in range(len(data)):
        with pytest.raises(CodecError, match="truncated|magic"):
            vbt.decode_bytes(data[:n])
    with pytest.raises(CodecError, match="trailing"):
        vbt.decode_bytes(data + b"\0")


def test_random_byte_flips_never_decode_silently(step, rng):
    _, traj, q = step
    data = bytearray(vbt.encode_bytes(traj, q))
    for _ in range(500):
        bad = bytearray(data)
        for pos in rng.choice(len(bad), size=rng.integers(1, 4), replace=False):
            bad[pos] ^= int(rng.integers(1, 256))
        with pytest.raises(CodecError):
            vbt.decode_bytes(bytes(bad))


def _recrc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def test_wrong_version_and_inconsistent_fields(step):
    _, traj, q = step
    data = vbt.encode_bytes(traj, q)
    body = bytearray(data[:-4])
    v2 = bytearray(body)
    v2[4:6] = struct.pack("<H", 2)
    with pytest.raises(CodecError, match="version 2 is not supported"):
        vbt.decode_bytes(_recrc(bytes(v2)))
    frames = bytearray(body)
    frames[60:64] = struct.pack("<I", traj.n_frames + 1)  # a well-formed CRC over wrong fields
    with pytest.raises(CodecError, match="frames"):
        vbt.decode_bytes(_recrc(bytes(frames)))
    flags = bytearray(body)
    flags[7] = 0x80
    with pytest.raises(CodecError, match="flags"):
        vbt.decode_bytes(_recrc(bytes(flags)))
    with pytest.raises(CodecError, match="magic"):
        vbt.decode_bytes(b"RIFF" + data[4:])


def test_read_vbt_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        vbt.read_vbt(tmp_path / "missing.vbt")
    p = tmp_path / "x.vbt"
    p.write_bytes(b"VBTR\x01")
    with pytest.raises(CodecError, match="truncated"):
        vbt.read_vbt(p)
