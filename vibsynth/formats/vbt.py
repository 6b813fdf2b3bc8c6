"""The ``.vbt`` file: a quantised (intensity, t1) trajectory, and decoding it through the engine.

Format, version 1 (all integers little-endian)
----------------------------------------------
======  ====  ==========  =====================================================
offset  size  type        field
======  ====  ==========  =====================================================
0       4     bytes       magic ``b"VBTR"``
4       2     uint16      format version (1)
6       1     uint8       bits per value (2..16)
7       1     uint8       flags: bit 0 = run-length records; other bits 0
8       8     float64     source sample rate (Hz)
16      12    ASCII       basis id (12 hex digits, :attr:`Basis.id`)
28      4     uint32      window (samples at the source rate)
32      4     uint32      hop (samples)
36      8     uint64      source length (samples)
44      4     float32     intensity range low (dB re unit RMS)
48      4     float32     intensity range high (dB)
52      4     float32     t1 range low
56      4     float32     t1 range high
60      4     uint32      n_frames: windows, ``(length - window) // hop + 1``
64      4     uint32      n_records
68      4     uint32      payload length (bytes)
72      ...   bytes       payload
end-4   4     uint32      CRC-32 (zlib) of every byte before it
======  ====  ==========  =====================================================

Payload: a big-endian bit stream of ``n_records`` records, zero-padded to a byte.
With run-length records (flag bit 0) a record is ``run`` (16 bits, windows, >= 1),
intensity code, t1 code (``bits`` each), and the runs sum to ``n_frames``;
otherwise ``n_records == n_frames`` and a record is the two codes of one window.
The encoder picks whichever is smaller. Codes: see
:class:`vibsynth.dsp.codec.Quantizer` (intensity code 0 = silent).

A file that is truncated, has trailing bytes, a wrong magic, an unknown version
or flags, a CRC mismatch, or inconsistent fields raises
:class:`~vibsynth.errors.CodecError` naming the problem; nothing is decoded from it.

Decoding (:func:`render`) schedules the trajectory as ``SetKnob`` commands at
exact frames, with glides, on the real-time :class:`~vibsynth.engine.engine.Engine`
and renders it: the same code that plays live.
"""

from __future__ import annotations

import math
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.codec import Quantizer, Trajectory, frame_count
from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.errors import CodecError, InputError, ParameterError

MAGIC = b"VBTR"
VERSION = 1
HEADER = struct.Struct("<4sHBBd12sIIQffffIII")
_CRC = struct.Struct("<I")
_FLAG_RLE = 1
_RUN_BITS = 16


def _pack_bits(values: NDArray[np.int64], widths: NDArray[np.int64]) -> bytes:
    """Big-endian bit stream of ``values[i]`` in ``widths[i]`` bits each."""
    if values.size == 0:
        return b""
    total = int(widths.sum())
    bits = np.zeros(total, dtype=np.uint8)
    ends = np.cumsum(widths)
    for w in np.unique(widths):
        sel = widths == w
        shifts = np.arange(int(w) - 1, -1, -1)
        b = (values[sel][:, None] >> shifts) & 1
        pos = (ends[sel] - int(w))[:, None] + np.arange(int(w))
        bits[pos.ravel()] = b.ravel()
    return np.packbits(bits).tobytes()


def _unpack_bits(data: bytes, widths: NDArray[np.int64]) -> NDArray[np.int64]:
    bits = np.unpackbits(np.frombuffer(data, dtype=np.uint8)).astype(np.int64)
    total = int(widths.sum())
    if np.any(bits[total:]):
        raise CodecError("corrupt payload: non-zero padding bits")
    out = np.zeros(widths.size, dtype=np.int64)
    ends = np.cumsum(widths)
    for w in np.unique(widths):
        sel = widths == w
        pos = (ends[sel] - int(w))[:, None] + np.arange(int(w))
        weights = 1 << np.arange(int(w) - 1, -1, -1)
        out[sel] = bits[pos] @ weights
    return out


def encode_bytes(trajectory: Trajectory, quantizer: Quantizer) -> bytes:
    """Serialise a trajectory with a quantiser.

    Parameters
    ----------
    trajectory : Trajectory
    quantizer : Quantizer

    Returns
    -------
    data : bytes
        A complete ``.vbt`` file.
    """
    if len(trajectory.basis_id) != 12 or not all(c in "0123456789abcdef" for c in trajectory.basis_id):
        raise ParameterError(f"basis id must be 12 hex digits, got {trajectory.basis_id!r}")
    if trajectory.n_frames != frame_count(trajectory.n_samples, trajectory.window, trajectory.hop):
        raise ParameterError("trajectory frame count does not match its length, window and hop")
    lc, tc = quantizer.encode(trajectory.level_db, trajectory.t1)
    n = lc.size
    bits = int(quantizer.bits)
    # Run-length records over runs of identical code pairs (split at 2**16 - 1 windows).
    change = np.flatnonzero((np.diff(lc) != 0) | (np.diff(tc) != 0)) + 1
    starts = np.concatenate(([0], change))
    runs = np.diff(np.concatenate((starts, [n])))
    rec_l, rec_t, rec_r = [], [], []
    for s, r in zip(starts.tolist(), runs.tolist()):
        while r > 0:
            step = min(r, (1 << _RUN_BITS) - 1)
            rec_r.append(step)
            rec_l.append(int(lc[s]))
            rec_t.append(int(tc[s]))
            r -= step
    rle_bits = len(rec_r) * (_RUN_BITS + 2 * bits)
    if rle_bits < n * 2 * bits:
        flags = _FLAG_RLE
        values = np.column_stack([rec_r, rec_l, rec_t]).ravel()
        widths = np.tile([_RUN_BITS, bits, bits], len(rec_r))
        n_records = len(rec_r)
    else:
        flags = 0
        values = np.column_stack([lc, tc]).ravel()
        widths = np.full(values.size, bits)
        n_records = n
    payload = _pack_bits(np.asarray(values, dtype=np.int64), np.asarray(widths, dtype=np.int64))
    header = HEADER.pack(
        MAGIC,
        VERSION,
        bits,
        flags,
        float(trajectory.fs),
        trajectory.basis_id.encode("ascii"),
        trajectory.window,
        trajectory.hop,
        trajectory.n_samples,
        quantizer.level_lo,
        quantizer.level_hi,
        quantizer.t1_lo,
        quantizer.t1_hi,
        n,
        n_records,
        len(payload),
    )
    body = header + payload
    return body + _CRC.pack(zlib.crc32(body) & 0xFFFFFFFF)


@dataclass(frozen=True)
class Decoded:
    """A decoded ``.vbt`` file.

    Attributes
    ----------
    trajectory : Trajectory
        Dequantised values per window.
    quantizer : Quantizer
    n_records : int
    run_length : bool
    size_bytes : int
    """

    trajectory: Trajectory
    quantizer: Quantizer
    n_records: int
    run_length: bool
    size_bytes: int


def decode_bytes(data: bytes, *, name: str = "file") -> Decoded:
    """Parse and check a ``.vbt`` file.

    Raises
    ------
    CodecError
        Anything wrong with the bytes (the message says what).
    """
    n_min = HEADER.size + _CRC.size
    if data[:4] != MAGIC[: len(data[:4])]:
        raise CodecError(f"{name}: not a vibsynth trajectory file (bad magic)")
    if len(data) < n_min:
        raise CodecError(f"{name}: truncated: {len(data)} bytes, a header alone takes {n_min}")
    (
        magic,
        version,
        bits,
        flags,
        fs,
        basis_id,
        window,
        hop,
        n_samples,
        l_lo,
        l_hi,
        t_lo,
        t_hi,
        n_frames,
        n_records,
        payload_len,
    ) = HEADER.unpack_from(data)
    if version != VERSION:
        raise CodecError(f"{name}: format version {version} is not supported (this vibsynth reads version {VERSION})")
    expected = HEADER.size + payload_len + _CRC.size
    if len(data) < expected:
        raise CodecError(f"{name}: truncated: {len(data)} bytes, the header announces {expected}")
    if len(data) > expected:
        raise CodecError(f"{name}: {len(data) - expected} unexpected trailing bytes")
    (crc,) = _CRC.unpack_from(data, expected - _CRC.size)
    if zlib.crc32(data[: expected - _CRC.size]) & 0xFFFFFFFF != crc:
        raise CodecError(f"{name}: corrupt (CRC-32 mismatch)")
    # The CRC matched: remaining checks catch files written wrongly, not damaged ones.
    if flags & ~_FLAG_RLE:
        raise CodecError(f"{name}: unknown flags 0x{flags:02x}")
    try:
        bid = basis_id.decode("ascii")
    except UnicodeDecodeError:
        raise CodecError(f"{name}: basis id is not ASCII") from None
    if len(bid) != 12 or not all(c in "0123456789abcdef" for c in bid):
        raise CodecError(f"{name}: malformed basis id {bid!r}")
    if not (math.isfinite(fs) and fs >= MIN_RATE_HZ and fs < 1e7):
        raise CodecError(f"{name}: invalid sample rate {fs}")
    if window < 16 or hop < 1 or hop > window or n_samples < window:
        raise CodecError(f"{name}: inconsistent window {window}, hop {hop}, length {n_samples}")
    if n_frames != frame_count(n_samples, window, hop):
        raise CodecError(f"{name}: {n_frames} frames do not match length {n_samples}, window {window}, hop {hop}")
    try:
        quantizer = Quantizer(int(bits), float(l_lo), float(l_hi), float(t_lo), float(t_hi))
    except ParameterError as exc:
        raise CodecError(f"{name}: {exc}") from None
    rle = bool(flags & _FLAG_RLE)
    if rle:
        if not 1 <= n_records <= n_frames:
            raise CodecError(f"{name}: {n_records} records for {n_frames} frames")
        widths = np.tile(np.array([_RUN_BITS, bits, bits], dtype=np.int64), n_records)
    else:
        if n_records != n_frames:
            raise CodecError(f"{name}: {n_records} records for {n_frames} frames")
        widths = np.full(2 * n_records, bits, dtype=np.int64)
    if payload_len != (int(widths.sum()) + 7) // 8:
        raise CodecError(f"{name}: payload of {payload_len} bytes does not hold {n_records} records")
    values = _unpack_bits(data[HEADER.size : HEADER.size + payload_len], widths)
    if rle:
        rec = values.reshape(-1, 3)
        runs = rec[:, 0]
        if np.any(runs < 1) or int(runs.sum()) != n_frames:
            raise CodecError(f"{name}: run lengths do not add up to {n_frames} frames")
        lc, tc = np.repeat(rec[:, 1], runs), np.repeat(rec[:, 2], runs)
    else:
        rec = values.reshape(-1, 2)
        lc, tc = rec[:, 0], rec[:, 1]
    level, t1 = quantizer.decode(lc, tc)
    if np.all(~np.isfinite(level)):
        raise CodecError(f"{name}: every window is silent")
    traj = Trajectory(float(fs), int(n_samples), int(window), int(hop), level, t1, bid)
    return Decoded(traj, quantizer, int(n_records), rle, len(data))


def write_vbt(path: str | os.PathLike[str], trajectory: Trajectory, quantizer: Quantizer) -> int:
    """Write a ``.vbt`` file atomically; returns its size in bytes."""
    from vibsynth.formats.files import atomic_write_bytes

    data = encode_bytes(trajectory, quantizer)
    atomic_write_bytes(path, data)
    return len(data)


def read_vbt(path: str | os.PathLike[str]) -> Decoded:
    """Read and check a ``.vbt`` file.

    Raises
    ------
    InputError
        Missing or unreadable file.
    CodecError
        Corrupt, truncated or of an unsupported version.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror})") from None
    return decode_bytes(data, name=str(p))
