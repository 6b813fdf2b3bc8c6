"""``vibsynth analyze``: intensity, balance and spectrum of recordings."""

from __future__ import annotations

import argparse
import math

from vibsynth.cli._common import add_basis_argument, basis_from_args, sample_rate
from vibsynth.cli._inputs import add_recursive_argument, expand_recordings, wav_channel
from vibsynth.cli._table import Column, add_format_argument, emit, output_format
from vibsynth.dsp.analysis import Analysis, analyze
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.recordings import read_recording
from vibsynth.settings.actuators import profile_intensity

ORDER = 10

HELP = """\
Measure each recording's two perceptual attributes:
  level    intensity: 80-200 Hz Butterworth band level, dB re unit RMS (WAV full scale = 1); with
           --profile NAME the felt level in that calibrated profile's own weighting (the recording
           is taken as what the actuator does, e.g. an accelerometer's; docs/calibration.md)
  knob     the intensity knob (0..1) that renders this level (outside 0..1: out of knob range)
  balance  high/low balance in knob units (0 = mean spectrum M, +-1 = 98th/2nd percentile of the
           basis' database, + = brighter); '*' marks a recording outside the database's range
  t1       raw first PCA score;  nonstat  std of the level over 100 ms windows (dB)
--format json (or --json) adds the 8 scores T1..T8 and the 30-band dB spectrum; --format csv
gives the table's columns as numbers. Folders are walked with --recursive.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="measure intensity and high/low balance of recordings",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="WAV, or CSV/TXT with one column of samples; or a folder")
    add_recursive_argument(p)
    p.add_argument("--rate", type=sample_rate, metavar="HZ", help="sample rate of CSV/TXT files")
    p.add_argument(
        "--channel", type=wav_channel, default=0, metavar="N", help="channel of a multi-channel WAV (1 = the first)"
    )
    add_format_argument(p)
    p.add_argument("--ceiling-db", type=float, default=DEFAULT_CEILING_DB, help="intensity knob ceiling (dB)")
    p.add_argument("--range-db", type=float, default=DEFAULT_RANGE_DB, help="intensity knob range (dB)")
    p.add_argument(
        "--profile",
        metavar="NAME",
        help="measure intensity as on this actuator profile's device: its calibrated weighting (default: the "
        "paper's 80-200 Hz band, also for a profile without a calibration)",
    )
    add_basis_argument(p)
    p.set_defaults(func=run)


def intensity_of_args(args: argparse.Namespace) -> IntensityWeighting:
    """``--profile NAME``'s intensity weighting, or the paper's band."""
    name = getattr(args, "profile", None)
    return PAPER_WEIGHTING if name is None else profile_intensity(name)


def analyze_file(
    path: str, args: argparse.Namespace, basis, weighting: IntensityWeighting = PAPER_WEIGHTING
) -> Analysis:
    rec = read_recording(path, fs=args.rate, channel=getattr(args, "channel", 0))
    try:
        return analyze(
            rec.samples,
            fs=rec.fs,
            basis=basis,
            ceiling_db=args.ceiling_db,
            range_db=args.range_db,
            weighting=weighting,
        )
    except ParameterError as exc:
        raise InputError(f"{path}: {exc}") from None


def _level(value: float) -> str:
    return f"{value:.2f}" if math.isfinite(value) else "-inf"


COLUMNS = (
    Column("file", "file", name=True),
    Column("duration_s", "dur s", lambda v: f"{v:.2f}"),
    Column("fs", "rate Hz", lambda v: f"{v:.0f}"),
    Column("level_db", "level dB", _level),
    Column("intensity_knob", "knob", lambda v: f"{v:.3f}"),
    Column("balance", "balance", lambda v: f"{v:+.3f}"),
    Column("outside", "", lambda v: "*" if v else ""),
    Column("t1", "t1", lambda v: f"{v:+.2f}"),
    Column("non_stationarity_db", "nonstat", lambda v: f"{v:.2f}"),
)


def _row(path: str, a: Analysis) -> dict[str, object]:
    return {
        "file": path,
        "duration_s": a.duration_s,
        "fs": a.fs,
        "level_db": a.level_db,
        "intensity_knob": a.intensity_knob,
        "balance": a.balance,
        "outside": a.outside_database,
        "t1": a.t1,
        "non_stationarity_db": a.non_stationarity_db,
    }


def run(args: argparse.Namespace) -> int:
    fmt = output_format(args)
    files = [str(p) for p in expand_recordings(args.files, recursive=args.recursive)]
    basis = basis_from_args(args)
    weighting = intensity_of_args(args)
    results = [(path, analyze_file(path, args, basis, weighting)) for path in files]
    rows = [_row(p, a) for p, a in results]
    extra = {} if weighting.is_paper else {"intensity": weighting.describe()}
    emit(rows, COLUMNS, fmt, json_rows=[{"file": p, "basis_id": basis.id, **extra, **a.to_dict()} for p, a in results])
    if fmt == "table" and not weighting.is_paper:
        print(f"level: intensity in {weighting.describe()}")
    if fmt == "table" and any(a.outside_database for _, a in results):
        print(f"* outside the t1 range of the basis' database ({basis.t1_min:.1f} .. {basis.t1_max:.1f})")
    return 0
