"""``vibsynth compare A B [C ...]``: the paper's dissimilarity D between recordings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from vibsynth.cli._common import add_basis_argument, basis_from_args, sample_rate
from vibsynth.cli._inputs import add_recursive_argument, expand_recordings
from vibsynth.cli._table import Column, add_format_argument, emit, output_format
from vibsynth.dsp.dissimilarity import PAPER_WEIGHTS, check_weights, dissimilarity_matrix
from vibsynth.errors import ParameterError

ORDER = 50


def _weights(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated numbers, e.g. 1,0,0.2") from None
    if not values:
        raise argparse.ArgumentTypeError("no weights given")
    return values


def one_per_component(weights: list[float], n_components: int) -> list[float]:
    """The weights a person typed, refused unless there is exactly one per score component.

    The library pads a short vector with zeros; on the command line, two numbers for eight
    components is more likely a mistake than a wish, so it is named instead.
    """
    if len(weights) != n_components:
        example = ",".join(["1"] + ["0"] * (n_components - 1))
        raise ParameterError(
            f"--weights: {len(weights)} value(s) given; give {n_components}, one per score component "
            f"of the basis (e.g. {example})"
        )
    return weights


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compare",
        help="dissimilarity D between recordings (paper's model: |t1 difference| by default)",
        description="D(x, y) = sum_j w_j |T_xj - T_yj| over the 8 PCA scores. Default weights: the paper's "
        "finding (first component only), so D = |t1_x - t1_y| in t1 units. Two files: one D; more: a matrix.",
    )
    p.add_argument(
        "files", nargs="+", type=Path, metavar="FILE", help="recordings (.wav, .csv/.txt with --rate), or folders"
    )
    add_recursive_argument(p)
    p.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    p.add_argument(
        "--weights",
        type=_weights,
        metavar="W1,W2,...",
        help="weights (e.g. from `vibsynth dissim fit`); default 1,0,0,0,0,0,0,0",
    )
    add_format_argument(p)
    add_basis_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vibsynth.research.dissim import scores_for_files

    fmt = output_format(args)
    files = expand_recordings(args.files, recursive=args.recursive)
    if len(files) < 2:
        raise ParameterError("compare needs at least two recordings")
    basis = basis_from_args(args)
    weights = check_weights(
        PAPER_WEIGHTS if args.weights is None else one_per_component(args.weights, basis.n_components),
        basis.n_components,
    )
    scores = scores_for_files(files, basis=basis, fs=args.rate)
    d = dissimilarity_matrix(scores, weights)
    names = [str(f) for f in files]
    if fmt == "csv":
        rows = [
            {"file_a": names[i], "file_b": names[j], "D": float(d[i, j])}
            for i in range(len(names))
            for j in range(i + 1, len(names))
        ]
        emit(rows, (Column("file_a", "file_a"), Column("file_b", "file_b"), Column("D", "D")), "csv")
        return 0
    if fmt == "json":
        out = {
            "weights": weights.tolist(),
            "basis": basis.id,
            "files": names,
            "t1": scores[:, 0].tolist(),
            "matrix": d.tolist(),
        }
        if len(names) == 2:
            out["D"] = float(d[0, 1])
        print(json.dumps(out, indent=2))
        return 0
    if len(names) == 2:
        print(f"D = {d[0, 1]:.3f}   ({names[0]}: t1 = {scores[0, 0]:+.2f}, {names[1]}: t1 = {scores[1, 0]:+.2f})")
        return 0
    columns = [Column("n", "#", lambda v: f"[{v}]"), Column("file", "file", name=True)]
    columns += [Column(f"d{j}", f"[{j + 1}]", lambda v: f"{v:.2f}") for j in range(len(names))]
    rows = [
        {"n": i + 1, "file": n, **{f"d{j}": float(d[i, j]) for j in range(len(names))}} for i, n in enumerate(names)
    ]
    emit(rows, columns, "table")
    print(f"(D in t1 units with weights {np.array2string(weights, precision=3, separator=',')})")
    return 0
