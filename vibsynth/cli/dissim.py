"""``vibsynth dissim fit RATINGS.csv``: fit the dissimilarity weights the paper's way."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from vibsynth.cli._common import Progress, add_basis_argument, basis_from_args, integer_in, sample_rate
from vibsynth.cli._table import Column, add_format_argument, emit, output_format

if TYPE_CHECKING:
    from vibsynth.research.dissim import DissimilarityFit

ORDER = 52


_positive_int = integer_in(1)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("dissim", help="dissimilarity model: fit weights to ratings (paper's Lasso)")
    sub = p.add_subparsers(dest="dissim_command", metavar="ACTION", required=True)
    fit = sub.add_parser(
        "fit",
        help="fit D's weights to a ratings table (Lasso, 10-fold CV, 80/20 splits)",
        description="RATINGS.csv has rows file_a,file_b,rating (optional header; files relative to the CSV). "
        "Fits rating ~ b0 + sum_j w_j |T_aj - T_bj| by non-negative Lasso, penalty by 10-fold CV, on 80 %% of the "
        "pairs, tested on 20 %%, over --splits random splits; prints mean/SD test R^2, the weights and the R^2 of "
        "each component alone and of the first i components (the paper's Fig. 6b). Needs scikit-learn.",
    )
    fit.add_argument("ratings", type=Path, metavar="RATINGS.csv")
    fit.add_argument("--splits", type=_positive_int, default=100, help="random 80/20 splits (default 100)")
    fit.add_argument("--seed", type=int, default=0, help="seed of the splits and folds (default 0)")
    fit.add_argument("--cv", type=_positive_int, default=10, help="cross-validation folds (default 10)")
    fit.add_argument(
        "--solver",
        choices=("lars", "cd"),
        default="lars",
        help="lars = LassoLarsCV (exact path, fast); cd = LassoCV (coordinate descent)",
    )
    fit.add_argument("--allow-negative", action="store_true", help="do not constrain weights to be >= 0")
    fit.add_argument("--no-self-pairs", action="store_true", help="ignore ratings of a file with itself")
    fit.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    add_format_argument(fit)
    add_basis_argument(fit)
    fit.set_defaults(func=run_fit)


def run_fit(args: argparse.Namespace) -> int:
    from vibsynth.research.dissim import fit_from_ratings, read_ratings, require_sklearn, scores_for_files

    require_sklearn("vibsynth dissim fit")
    table = read_ratings(args.ratings)
    basis = basis_from_args(args)
    scores = scores_for_files(table.files, basis=basis, fs=args.rate, progress=Progress("analysing"))
    fit = fit_from_ratings(
        table,
        scores,
        include_self_pairs=not args.no_self_pairs,
        n_splits=args.splits,
        seed=args.seed,
        cv=args.cv,
        positive=not args.allow_negative,
        solver=args.solver,
    )
    fmt = output_format(args)
    if fmt == "csv":
        emit_weights_csv(fit)
        return 0
    if fmt == "json":
        out = fit.to_dict()
        out.update(
            {
                "ratings": str(table.path),
                "files": [str(f) for f in table.files],
                "basis": basis.id,
                "n_rows": table.n_rows,
            }
        )
        print(json.dumps(out, indent=2))
        return 0
    print(
        f"{table.n_rows} ratings -> {fit.n_pairs} pairs of {len(table.files)} recordings (basis {basis.id}); ", end=""
    )
    print_fit(fit)
    return 0


def weight_rows(fit: DissimilarityFit) -> list[dict[str, float | str]]:
    """One row per score component: its weights, how often it was selected, its R^2 alone and with the first i."""
    return [
        {
            "component": f"T{j + 1}",
            "weight": float(fit.weights[j]),
            "weight_mean": float(fit.weights_mean[j]),
            "weight_sd": float(fit.weights_sd[j]),
            "selected_fraction": float(fit.selected_fraction[j]),
            "r2_alone": float(fit.r2_single_mean[j]),
            "r2_first_i": float(fit.r2_first_mean[j]),
        }
        for j in range(fit.weights.size)
    ]


def emit_weights_csv(fit: DissimilarityFit) -> None:
    """The weights as CSV on stdout (``dissim fit --format csv``, ``lab analyze --format csv``)."""
    rows = weight_rows(fit)
    emit(rows, [Column(key, key) for key in rows[0]], "csv")


def print_fit(fit: DissimilarityFit) -> None:
    """The fit for people: splits, held-out R^2 beside the paper's, the weights and Fig. 6b's numbers."""
    print(
        f"{fit.n_splits} splits of {fit.n_train} train / {fit.n_test} test, "
        f"{fit.cv}-fold CV, {'non-negative ' if fit.positive else ''}Lasso ({fit.solver})"
    )
    print(f"test R^2 = {fit.r2_mean:.3f} (SD {fit.r2_sd:.3f})      [paper: 0.54, SD 0.11]")
    print(f"intercept (identical pair) = {fit.intercept:.4f}; penalty alpha = {fit.alpha:.3g}")
    print("component   weight (all pairs)   mean +- SD over splits   selected   R^2 alone   R^2 first i")
    for j in range(fit.weights.size):
        print(
            f"  T{j + 1:<8} {fit.weights[j]:>14.5f}   {fit.weights_mean[j]:>10.5f} +- {fit.weights_sd[j]:<9.5f}"
            f" {100 * fit.selected_fraction[j]:>7.0f} %   {fit.r2_single_mean[j]:>9.3f}   {fit.r2_first_mean[j]:>10.3f}"
        )
