"""``vibsynth basis``: fit a spectral basis from recordings or PSDs, or show one."""

from __future__ import annotations

import argparse
from pathlib import Path

from vibsynth.cli._common import Progress, add_basis_argument, basis_from_args, sample_rate
from vibsynth.dsp.basis import Basis
from vibsynth.errors import InputError
from vibsynth.formats.basis_file import save_basis
from vibsynth.research.basis_fit import fit_from_psd_table, fit_from_recordings

ORDER = 30


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("basis", help="fit or show a spectral basis (M, V1..V8)")
    sub = p.add_subparsers(dest="basis_command", metavar="ACTION", required=True)
    fit = sub.add_parser(
        "fit",
        help="fit a basis by PCA",
        description="Fit M and V1..V8 by PCA over level-normalised 30-band dB spectra. SRC is a folder of "
        "recordings (.wav, or .csv/.txt with --rate) or a PSD table (.csv or .csv.gz whose frequency "
        "columns have numeric headers in Hz, like shared/datasets/hatt-psd/psd.csv.gz).",
    )
    fit.add_argument("source", metavar="SRC", type=Path)
    fit.add_argument("-o", "--output", required=True, type=Path, metavar="FILE.yaml")
    fit.add_argument("--rate", type=sample_rate, metavar="HZ", help="sample rate of CSV/TXT recordings")
    fit.set_defaults(func=run_fit)
    show = sub.add_parser("show", help="print a basis (default: the shipped one)")
    add_basis_argument(show)
    show.add_argument("file", nargs="?", type=Path, help="basis YAML (same as --basis)")
    show.set_defaults(func=run_show)


def run_fit(args: argparse.Namespace) -> int:
    src: Path = args.source
    if src.is_dir():
        basis = fit_from_recordings(src, fs=args.rate, progress=Progress("fitting"))
    elif src.is_file():
        basis = fit_from_psd_table(src)
    else:
        raise InputError(f"{src}: no such file or folder")
    save_basis(basis, args.output)
    print(f"wrote {args.output}: basis {basis.id} from {basis.n_spectra} spectra")
    print(summary(basis))
    return 0


def summary(basis: Basis) -> str:
    """Human-readable description of a basis."""
    evr = basis.explained_variance_ratio
    pct = basis.t1_percentiles
    lines = [
        f"id                 {basis.id}",
        f"spectra            {basis.n_spectra}",
        f"bands              {basis.n_bands} ({basis.centres_hz[0]:g}-{basis.centres_hz[-1]:g} Hz), "
        f"Butterworth order {basis.filter_order}",
        "explained variance " + " ".join(f"V{i + 1}={v:.1%}" for i, v in enumerate(evr)) + f"  (total {evr.sum():.2%})",
        f"t1 percentiles     p2={pct[2.0]:.2f}  p50={pct[50.0]:.2f}  p98={pct[98.0]:.2f}  "
        f"range {basis.t1_min:.2f}..{basis.t1_max:.2f} (balance {basis.balance_from_t1(basis.t1_min):+.2f}.."
        f"{basis.balance_from_t1(basis.t1_max):+.2f})",
    ]
    for key, value in basis.provenance.items():
        lines.append(f"{key:<18} {value}")
    lines.append("")
    lines.append(
        f"{'band Hz':>9} {'M dB':>8} " + " ".join(f"{'V' + str(i + 1):>6}" for i in range(min(3, basis.n_components)))
    )
    for k, fc in enumerate(basis.centres_hz):
        comps = " ".join(f"{basis.components[i, k]:+6.3f}" for i in range(min(3, basis.n_components)))
        lines.append(f"{fc:9.1f} {basis.mean_db[k]:+8.2f} {comps}")
    return "\n".join(lines)


def run_show(args: argparse.Namespace) -> int:
    if args.file is not None:
        args.basis = args.file
    print(summary(basis_from_args(args)))
    return 0


__all__ = ["summary", "register"]
