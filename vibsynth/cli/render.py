"""``vibsynth render``: a texture (or a recording's paper variant, or a MIDI performance) to a WAV file."""

from __future__ import annotations

import argparse
import logging
import math
import sys

import numpy as np

from vibsynth.cli._common import (
    add_basis_argument,
    basis_from_args,
    finite_float,
    positive_seconds,
    sample_rate,
    unit_interval,
)
from vibsynth.cli.analyze import analyze_file
from vibsynth.dsp.analysis import VARIANTS, variant_spectra
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, knob_to_level_db
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import write_wav

ORDER = 20

log = logging.getLogger(__name__)

HELP = """\
Render noise with the paper's spectrum model to a WAV file (a seamless loop of the given length):
  --balance B --intensity I   the spectrum M + t1(B) V1 at intensity knob I (0..1; see --ceiling-db)
  --from FILE --variant V     a recording's experiment-3 variant at the recording's own level:
                              S1 = M + t1 V1, S1:8 = all 8 components, S2:8 = all but the first, M = mean
  --midi FILE.mid             a MIDI performance through the live MIDI mapping and the real-time engine
The band powers of the result match the target within rounding (closed-form synthesis).
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "render",
        help="render a texture to a WAV file",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--balance", type=finite_float, metavar="B", help="high/low balance (knob units)")
    source.add_argument("--from", dest="from_file", metavar="FILE", help="recording to re-synthesize")
    source.add_argument("--midi", metavar="FILE.mid", help="MIDI file to render through the MIDI mapping")
    p.add_argument("--intensity", type=unit_interval, metavar="I", help="intensity knob 0..1 (with --balance)")
    p.add_argument("--channel", type=int, default=0, metavar="N", help="channel of a multi-channel WAV (with --from)")
    p.add_argument("--variant", choices=list(VARIANTS), default="S1", help="variant (with --from; default S1)")
    p.add_argument("--seconds", type=positive_seconds, default=None, metavar="S", help="duration (default 4 s)")
    p.add_argument(
        "--rate",
        type=sample_rate,
        default=None,
        metavar="HZ",
        help="output rate (default 48000; with --from, the recording's rate; also the rate of CSV/TXT input)",
    )
    p.add_argument("-o", "--output", required=True, metavar="OUT.wav", help="WAV file to write")
    p.add_argument("--format", choices=("float32", "pcm16"), default="float32", help="WAV sample format")
    p.add_argument("--seed", type=int, default=None, help="random phases (default: fresh)")
    p.add_argument("--ceiling-db", type=finite_float, default=DEFAULT_CEILING_DB, help="intensity knob ceiling (dB)")
    p.add_argument("--range-db", type=finite_float, default=DEFAULT_RANGE_DB, help="intensity knob range (dB)")
    p.add_argument("--config", metavar="FILE", help="config file (with --midi)")
    add_basis_argument(p)
    p.set_defaults(func=run)


def _render_midi(args: argparse.Namespace) -> tuple[np.ndarray, float]:
    try:
        from vibsynth.app.midi_render import render_midi_file
    except ImportError as exc:
        raise InputError(f"MIDI rendering is unavailable: {exc}") from None
    from vibsynth.settings.config import load_config

    overrides = {"audio": {"rate": int(args.rate)}} if args.rate else None
    config = load_config(args.config, overrides=overrides)
    try:
        from vibsynth.settings.library import load_library

        presets = load_library(config)
    except ImportError:
        presets = None
    return render_midi_file(
        args.midi, config=config, basis=basis_from_args(args), seconds=args.seconds, presets=presets
    )


def run(args: argparse.Namespace) -> int:
    if args.midi:
        samples, fs = _render_midi(args)
        _write(args, samples, fs)
        return 0
    basis = basis_from_args(args)
    seconds = args.seconds or 4.0
    rng = np.random.default_rng(args.seed)
    if args.balance is not None:
        if args.intensity is None:
            raise ParameterError("--balance needs --intensity I (0..1)")
        if args.intensity == 0.0:
            raise ParameterError("--intensity 0 is silence; nothing to render")
        analysis = None
        fs = args.rate or 48000.0
    else:
        analysis = analyze_file(args.from_file, args, basis)
        fs = args.rate or analysis.fs
    shaper = SpectralShaper(
        fs=fs, n_samples=int(round(seconds * fs)), centres=basis.centres_hz, order=basis.filter_order
    )
    if analysis is None:
        level = knob_to_level_db(args.intensity, ceiling_db=args.ceiling_db, range_db=args.range_db)
        weights = shaper.solve_balance(basis, args.balance, level_db=level)
    else:
        weights = shaper.solve_weights(variant_spectra(analysis, basis)[args.variant], level_db=analysis.level_db)
    signal = shaper.render(shaper.power_envelope(weights), shaper.random_phases(rng))
    _write(args, signal, fs)
    return 0


def _write(args: argparse.Namespace, samples: np.ndarray, fs: float) -> None:
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if peak >= 1.0:
        message = f"peak {peak:.2f} exceeds full scale (lower --intensity or --ceiling-db)"
        if args.format == "pcm16":
            raise ParameterError(message + "; pcm16 would clip")
        print(f"vibsynth: warning: {message}; float32 WAV keeps it unclipped", file=sys.stderr)
    write_wav(args.output, samples, fs, sample_format=args.format)
    db = 20 * math.log10(peak) if peak > 0 else -math.inf
    print(f"wrote {args.output}: {samples.shape[0] / fs:.2f} s at {fs:g} Hz, peak {db:.1f} dBFS")
