"""``vibsynth plot basis | spectrum | presets | mds``: PNG figures of the paper's analyses."""

from __future__ import annotations

import argparse
from pathlib import Path

from vibsynth.cli._common import add_basis_argument, basis_from_args, sample_rate
from vibsynth.cli._inputs import add_recursive_argument, expand_recordings
from vibsynth.errors import InputError, ParameterError

ORDER = 60


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("plot", help="PNG figures: basis, spectrum, presets, MDS map (needs matplotlib)")
    sub = p.add_subparsers(dest="plot_command", metavar="FIGURE", required=True)

    def common(q: argparse.ArgumentParser, default: str) -> None:
        q.add_argument(
            "-o",
            "--output",
            type=Path,
            default=Path(default),
            metavar="FILE.png",
            help=f"PNG to write (default {default})",
        )
        add_basis_argument(q)

    q = sub.add_parser("basis", help="M and V1..V8 over frequency (paper Fig. 6a)")
    common(q, "basis.png")
    q.set_defaults(func=run_basis)
    q = sub.add_parser("spectrum", help="measured spectra vs S1 and S1:8 reconstructions (Fig. 6c)")
    q.add_argument("files", nargs="+", type=Path, metavar="FILE", help="recordings, or folders with --recursive")
    add_recursive_argument(q)
    q.add_argument("--variants", action="store_true", help="also draw S2:8 and M")
    q.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    common(q, "spectrum.png")
    q.set_defaults(func=run_spectrum)
    q = sub.add_parser("presets", help="presets on the balance axis")
    q.add_argument("--config", type=Path, metavar="FILE.yaml", help="config (user preset folder)")
    common(q, "presets.png")
    q.set_defaults(func=run_presets)
    q = sub.add_parser("mds", help="2-D perceptual map of a ratings table (Fig. 7)")
    q.add_argument("ratings", type=Path, metavar="RATINGS.csv")
    q.add_argument("--weights", metavar="W1,W2,...", help="model weights (default: the paper's, first component)")
    q.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    common(q, "mds.png")
    q.set_defaults(func=run_mds)


def _done(path: Path) -> int:
    print(f"wrote {path}")
    return 0


def run_basis(args: argparse.Namespace) -> int:
    from vibsynth.research.plots import plot_basis

    return _done(plot_basis(basis_from_args(args), args.output))


def run_spectrum(args: argparse.Namespace) -> int:
    from vibsynth.dsp.analysis import analyze
    from vibsynth.formats.recordings import read_recording
    from vibsynth.research.plots import plot_spectrum

    basis = basis_from_args(args)
    spectra = []
    for f in expand_recordings(args.files, recursive=args.recursive):
        rec = read_recording(f, fs=args.rate)
        try:
            spectra.append((rec.path.name, analyze(rec.samples, fs=rec.fs, basis=basis).band_db))
        except ParameterError as exc:
            raise InputError(f"{rec.path}: {exc}") from None
    return _done(plot_spectrum(spectra, basis, args.output, variants=args.variants))


def run_presets(args: argparse.Namespace) -> int:
    from vibsynth.research.plots import plot_presets
    from vibsynth.settings.config import load_config
    from vibsynth.settings.library import load_library

    library = load_library(load_config(args.config).settings)
    items = []
    for name in library.names():
        preset = library.get(name)
        items.append((name, float(preset.balance), float(preset.intensity)))
    return _done(plot_presets(items, basis_from_args(args), args.output))


def run_mds(args: argparse.Namespace) -> int:
    from vibsynth.cli.compare import one_per_component
    from vibsynth.dsp.dissimilarity import PAPER_WEIGHTS, check_weights
    from vibsynth.research.dissim import mds_map, read_ratings, scores_for_files
    from vibsynth.research.plots import plot_mds

    basis = basis_from_args(args)
    weights = PAPER_WEIGHTS
    if args.weights:
        try:
            typed = [float(v) for v in args.weights.split(",")]
            weights = check_weights(one_per_component(typed, basis.n_components), basis.n_components)
        except ValueError:
            raise ParameterError(f"--weights {args.weights!r}: expected comma-separated numbers") from None
    table = read_ratings(args.ratings)
    scores = scores_for_files(table.files, basis=basis, fs=args.rate)
    m = mds_map(table, scores, weights=weights)
    print(
        f"V1 vs MDS dimensions: r = {m.component_r[0, 0]:+.2f}, {m.component_r[0, 1]:+.2f}; "
        f"Procrustes RMS error {m.procrustes_rms:.3f}"
    )
    return _done(plot_mds(m, args.output, title=f"Perceptual space of {table.path.name}"))
