"""``vibsynth analyze``: intensity, balance and spectrum of recordings."""

from __future__ import annotations

import argparse
import json
import math

from vibsynth.cli._common import add_basis_argument, basis_from_args, sample_rate
from vibsynth.dsp.analysis import Analysis, analyze
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import read_recording

ORDER = 10

HELP = """\
Measure each recording's two perceptual attributes:
  level    intensity: 80-200 Hz Butterworth band level, dB re unit RMS (WAV full scale = 1)
  knob     the intensity knob (0..1) that renders this level (outside 0..1: out of knob range)
  balance  high/low balance in knob units (0 = mean spectrum M, +-1 = 98th/2nd percentile of the
           basis' database, + = brighter); '*' marks a recording outside the database's range
  t1       raw first PCA score;  nonstat  std of the level over 100 ms windows (dB)
--json adds the 8 scores T1..T8 and the 30-band dB spectrum.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="measure intensity and high/low balance of recordings",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="WAV, or CSV/TXT with one column of samples")
    p.add_argument("--rate", type=sample_rate, metavar="HZ", help="sample rate of CSV/TXT files")
    p.add_argument("--channel", type=int, default=0, metavar="N", help="channel of a multi-channel WAV (0-based)")
    p.add_argument("--json", action="store_true", help="print JSON (one object per file, in a list)")
    p.add_argument("--ceiling-db", type=float, default=DEFAULT_CEILING_DB, help="intensity knob ceiling (dB)")
    p.add_argument("--range-db", type=float, default=DEFAULT_RANGE_DB, help="intensity knob range (dB)")
    add_basis_argument(p)
    p.set_defaults(func=run)


def analyze_file(path: str, args: argparse.Namespace, basis) -> Analysis:
    rec = read_recording(path, fs=args.rate, channel=getattr(args, "channel", 0))
    try:
        return analyze(rec.samples, fs=rec.fs, basis=basis, ceiling_db=args.ceiling_db, range_db=args.range_db)
    except ParameterError as exc:
        raise InputError(f"{path}: {exc}") from None


def _row(name: str, a: Analysis) -> str:
    flag = "*" if a.outside_database else " "
    level = f"{a.level_db:8.2f}" if math.isfinite(a.level_db) else "    -inf"
    shown = name if len(name) <= 32 else "…" + name[-31:]
    return (
        f"{shown:<32} {a.duration_s:7.2f} {a.fs:8.0f} {level} {a.intensity_knob:6.3f} "
        f"{a.balance:+8.3f}{flag} {a.t1:+8.2f} {a.non_stationarity_db:7.2f}"
    )


def run(args: argparse.Namespace) -> int:
    basis = basis_from_args(args)
    results = [(path, analyze_file(path, args, basis)) for path in args.files]
    if args.json:
        print(json.dumps([{"file": p, "basis_id": basis.id, **a.to_dict()} for p, a in results], indent=2))
        return 0
    print(
        f"{'file':<32} {'dur s':>7} {'rate Hz':>8} {'level dB':>8} {'knob':>6} {'balance':>9} {'t1':>8} {'nonstat':>7}"
    )
    for path, a in results:
        print(_row(path, a))
    if any(a.outside_database for _, a in results):
        print(f"* outside the t1 range of the basis' database ({basis.t1_min:.1f} .. {basis.t1_max:.1f})")
    return 0
