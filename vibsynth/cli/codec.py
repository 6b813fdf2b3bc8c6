"""``vibsynth encode`` / ``vibsynth decode``: the time-windowed (intensity, t1) codec and .vbt files."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from vibsynth.cli._common import add_basis_argument, basis_from_args, finite_float, integer_in, number_in, sample_rate
from vibsynth.cli._progress import RenderProgress, add_quiet_argument
from vibsynth.errors import InputError, ParameterError

ORDER = 55

PAPER_RATE_HZ = 2800.0
#: A segment whose intensity is further than this from one of its windows' own means the
#: recording changes more than segments can say (real scans: up to 27 dB): code per window.
MAX_SEGMENT_ERROR_DB = 6.0


_bits = integer_in(2, 16, what="bits")
_ms = number_in(5.0, 10000.0, unit="ms")


def register(subparsers: argparse._SubParsersAction) -> None:
    enc = subparsers.add_parser(
        "encode",
        help="recording -> .vbt trajectory of (intensity, balance) per window",
        description="Analyses 100 ms windows (50 ms hop) into intensity (80-200 Hz level, dB) and t1, merges "
        "windows into stationary segments (changes kept above --tolerance-db / --tolerance-t1 when significant), "
        "quantises with --bits per value and writes a .vbt file (docs/research.md). Prints the compression "
        "ratio and, unless --no-check, the quality of the decoded result.",
    )
    enc.add_argument("input", type=Path, metavar="FILE")
    enc.add_argument("-o", "--output", type=Path, required=True, metavar="FILE.vbt")
    enc.add_argument("--bits", type=_bits, default=8, help="bits per value, 2..16 (default 8)")
    enc.add_argument("--window-ms", type=_ms, default=100.0, help="analysis window (default 100 ms)")
    enc.add_argument("--hop-ms", type=_ms, default=50.0, help="hop between windows (default 50 ms)")
    enc.add_argument(
        "--tolerance-db",
        type=finite_float,
        default=1.0,
        help="smallest intensity change kept between segments (default 1 dB)",
    )
    enc.add_argument(
        "--tolerance-t1",
        type=finite_float,
        default=2.0,
        help="smallest t1 change kept between segments (default 2 t1 units)",
    )
    enc.add_argument(
        "--per-window", action="store_true", help="no segmentation: code every window's own (noisy) values"
    )
    enc.add_argument(
        "--max-segment-error-db",
        type=number_in(0.0, 100.0, unit="dB"),
        default=MAX_SEGMENT_ERROR_DB,
        metavar="DB",
        help="if merging windows into segments moves a window's intensity by more than this, the recording "
        f"is not stationary enough for segments: code every window instead (default {MAX_SEGMENT_ERROR_DB:g} dB)",
    )
    enc.add_argument(
        "--keep-segments", action="store_true", help="keep the segments even when they are far from the windows"
    )
    enc.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    enc.add_argument("--no-check", action="store_true", help="skip decoding to measure the quality")
    enc.add_argument("--json", action="store_true", help="machine-readable report")
    add_basis_argument(enc)
    enc.set_defaults(func=run_encode)

    dec = subparsers.add_parser(
        "decode",
        help=".vbt -> WAV, rendered through the real-time engine",
        description="Schedules each window's intensity and balance as engine knob moves (linear glides between "
        "window centres) and renders them with the same engine as `vibsynth serve`. The file stores absolute "
        "levels; if they would exceed 0 dB or the engine's limiter, the output is rendered quieter and the "
        "offset is reported (--absolute scales the float WAV back).",
    )
    dec.add_argument("input", type=Path, metavar="FILE.vbt")
    dec.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.wav")
    dec.add_argument("--reference", type=Path, metavar="ORIGINAL", help="original recording: print quality vs it")
    dec.add_argument("--rate", type=sample_rate, help="output rate (default: the source rate)")
    dec.add_argument("--reference-rate", type=sample_rate, help="sample rate of a CSV/TXT reference (Hz)")
    dec.add_argument("--absolute", action="store_true", help="undo the level offset (float WAV may exceed +-1)")
    dec.add_argument("--config", type=Path, metavar="FILE.yaml", help="engine config (bank grid, limiter, cache)")
    dec.add_argument("--json", action="store_true", help="machine-readable report")
    add_quiet_argument(dec)
    add_basis_argument(dec)
    dec.set_defaults(func=run_decode)


def ratios(size_bytes: int, n_samples: int, fs: float) -> dict[str, float]:
    """Compression ratios of a file of ``size_bytes`` for a recording of ``n_samples`` at ``fs``."""
    duration = n_samples / fs
    return {
        "size_bytes": int(size_bytes),
        "duration_s": duration,
        "bytes_per_second": size_bytes / duration,
        "ratio_vs_pcm16_source": (2.0 * n_samples) / size_bytes,
        "ratio_vs_pcm8_2800hz": (duration * PAPER_RATE_HZ) / size_bytes,
    }


def _print_ratios(r: dict[str, float], fs: float) -> None:
    print(f"size: {r['size_bytes']} bytes for {r['duration_s']:.2f} s = {r['bytes_per_second']:.1f} bytes/s")
    print(
        f"compression: {r['ratio_vs_pcm16_source']:.0f}:1 vs 16-bit PCM at {fs:g} Hz; "
        f"{r['ratio_vs_pcm8_2800hz']:.0f}:1 vs 8-bit at 2.8 kHz (paper's reference)"
    )


def _print_quality(q: Any) -> None:
    print(
        f"band spectrum error (whole signal): RMS {q.band_error_rms_db:.2f} dB, max {q.band_error_max_db:.2f} dB "
        f"(shape only {q.shape_error_rms_db:.2f} dB; the S1 model's own floor {q.s1_model_error_rms_db:.2f} dB)"
    )
    print(
        f"band spectrum error per window (median): {q.window_band_error_db:.2f} dB "
        f"(includes 100 ms estimation noise of two independent noises)"
    )
    print(
        f"intensity error: whole {q.level_error_db:+.2f} dB; per window bias {q.window_level_bias_db:+.2f}, "
        f"RMS {q.window_level_rms_db:.2f}, max {q.window_level_max_db:.2f} dB"
    )
    print(
        f"dissimilarity D(original, decoded) = {q.dissimilarity:.2f} t1 units (per window median "
        f"{q.window_dissimilarity:.2f})"
    )
    print(
        f"non-stationarity: original {q.non_stationarity_original_db:.2f} dB, decoded "
        f"{q.non_stationarity_decoded_db:.2f} dB"
    )


def _basis_for(args: argparse.Namespace, basis_id: str) -> Any:
    basis = basis_from_args(args)
    if basis.id != basis_id:
        raise InputError(
            f"{args.input}: encoded with basis {basis_id}, but the basis given is {basis.id} "
            f"(pass the right one with --basis)"
        )
    return basis


def run_encode(args: argparse.Namespace) -> int:
    from vibsynth.app import vbt_render
    from vibsynth.dsp.codec import Quantizer, encode_trajectory, quality
    from vibsynth.formats import vbt
    from vibsynth.formats.recordings import read_recording

    if args.hop_ms > args.window_ms:
        raise ParameterError(f"--hop-ms ({args.hop_ms:g}) must not exceed --window-ms ({args.window_ms:g})")
    rec = read_recording(args.input, fs=args.rate)
    basis = basis_from_args(args)
    started = time.perf_counter()
    segmentation: dict[str, Any] = {"segments": not args.per_window}

    def encode(segment: bool) -> Any:
        try:
            return encode_trajectory(
                rec.samples,
                fs=rec.fs,
                basis=basis,
                window_s=args.window_ms / 1000,
                hop_s=args.hop_ms / 1000,
                segment=segment,
                tolerance_db=args.tolerance_db,
                tolerance_t1=args.tolerance_t1,
            )
        except ParameterError as exc:
            raise InputError(f"{rec.path}: {exc}") from None

    traj = encode(not args.per_window)
    if not args.per_window:
        segmentation["window_level_error_db"] = traj.window_level_error_db
        if traj.window_level_error_db > args.max_segment_error_db:
            note = (
                f"{rec.path}: not stationary: segments were up to {traj.window_level_error_db:.1f} dB off the "
                f"windows' own intensity (over --max-segment-error-db {args.max_segment_error_db:g}); "
                "coded every window instead"
            )
            if args.keep_segments:
                note = note.replace("coded every window instead", "kept the segments (--keep-segments)")
            else:
                traj = encode(False)
                segmentation.update(segments=False, fell_back=True)
            print(f"vibsynth: note: {note}", file=sys.stderr)
    quant = Quantizer.fit(traj, bits=args.bits)
    size = vbt.write_vbt(args.output, traj, quant)
    encode_s = time.perf_counter() - started
    decoded = vbt.decode_bytes(args.output.read_bytes(), name=str(args.output))
    report: dict[str, Any] = {
        "input": str(rec.path),
        "output": str(args.output),
        "fs": rec.fs,
        "n_samples": int(rec.samples.size),
        "bits": quant.bits,
        "window_ms": traj.window_s * 1000,
        "hop_ms": traj.hop_s * 1000,
        "n_frames": traj.n_frames,
        "n_records": decoded.n_records,
        "run_length": decoded.run_length,
        "level_range_db": [quant.level_lo, quant.level_hi],
        "level_step_db": quant.level_step,
        "t1_range": [quant.t1_lo, quant.t1_hi],
        "t1_step": quant.t1_step,
        "clipped_windows": quant.clipped(traj),
        "segmentation": segmentation,
        "encode_seconds": encode_s,
        **ratios(size, rec.samples.size, rec.fs),
    }
    if not args.no_check:
        rendered = vbt_render.render(decoded.trajectory, basis=basis)
        q = quality(
            rec.samples,
            rendered.signal,
            fs=rec.fs,
            decoded_fs=rendered.fs,
            basis=basis,
            offset_db=rendered.offset_db,
            window_s=traj.window_s,
            hop_s=traj.hop_s,
        )
        report["quality"] = q.to_dict()
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return 0
    print(
        f"{rec.path} -> {args.output}: {traj.n_frames} windows of {traj.window_s * 1000:g} ms "
        f"(hop {traj.hop_s * 1000:g} ms) in {decoded.n_records} {'segments' if decoded.run_length else 'records'}, "
        f"{quant.bits} bits/value (intensity step {quant.level_step:.3f} dB over "
        f"[{quant.level_lo:g}, {quant.level_hi:g}] dB; t1 step {quant.t1_step:.3f})"
    )
    _print_ratios(report, rec.fs)
    if "quality" in report:
        _print_quality(q)
    return 0


def run_decode(args: argparse.Namespace) -> int:
    import numpy as np

    from vibsynth.app import vbt_render
    from vibsynth.app.render import ArrayCollector, GainSink, TeeSink
    from vibsynth.dsp.codec import quality
    from vibsynth.formats import vbt
    from vibsynth.formats.recordings import read_recording
    from vibsynth.formats.wav_stream import WavStreamWriter, check_target

    started = time.perf_counter()
    try:
        check_target(args.output, writable=True)
    except OSError as exc:
        return _output_error(exc)
    decoded = vbt.read_vbt(args.input)
    traj = decoded.trajectory
    basis = _basis_for(args, traj.basis_id)
    ref = read_recording(args.reference, fs=args.reference_rate) if args.reference is not None else None
    rendered = vbt_render.prepare(traj, basis=basis, rate=args.rate, config_path=args.config)
    gain = 10.0 ** (rendered.offset_db / 20.0) if args.absolute else 1.0
    try:
        with (
            WavStreamWriter(args.output, rendered.fs, 1, frames=rendered.frames) as wav,
            RenderProgress("decode", rendered.frames, rendered.fs, quiet=args.quiet) as progress,
        ):
            sink: Any = wav
            if ref is not None:  # the quality check needs the whole decoded signal, as the reference is held whole
                sink = TeeSink(wav, ArrayCollector(rendered.frames, 1, np.float64, max_bytes=8 * rendered.frames))
            done = vbt_render.render_to(rendered, GainSink(sink, gain) if args.absolute else sink, progress=progress)
    except OSError as exc:
        return _output_error(exc)
    decode_s = time.perf_counter() - started
    report: dict[str, Any] = {
        "input": str(args.input),
        "output": str(args.output),
        "fs": rendered.fs,
        "offset_db": 0.0 if args.absolute else rendered.offset_db,
        "balance_clamped_windows": rendered.balance_clamped,
        "knob_events": rendered.n_events,
        "decode_seconds": decode_s,
        **ratios(decoded.size_bytes, traj.n_samples, traj.fs),
    }
    q = None
    if ref is not None:
        q = quality(
            ref.samples,
            done.output[1][:, 0],
            fs=ref.fs,
            decoded_fs=rendered.fs,
            basis=basis,
            offset_db=0.0 if args.absolute else rendered.offset_db,
            window_s=traj.window_s,
            hop_s=traj.hop_s,
        )
        report["quality"] = q.to_dict()
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return 0
    if rendered.balance_clamped:
        print(
            f"vibsynth: warning: {rendered.balance_clamped} windows lie outside the engine's balance range (clamped)",
            file=sys.stderr,
        )
    if args.quiet:
        return 0
    print(f"{args.input} -> {args.output}: {done.seconds:.2f} s at {rendered.fs:g} Hz, {rendered.n_events} knob moves")
    if rendered.offset_db > 0 and not args.absolute:
        print(
            f"level: rendered {rendered.offset_db:.1f} dB below the encoded absolute level "
            f"(engine limit; --absolute undoes it in the float WAV)"
        )
    _print_ratios(report, traj.fs)
    if q is not None:
        _print_quality(q)
    else:
        print("quality: give --reference ORIGINAL to compare with the original recording")
    return 0


def _output_error(exc: OSError) -> int:
    """One line for an output file that cannot be written (missing folder, a folder, permission); exit 1."""
    print(f"vibsynth: error: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
    return 1
