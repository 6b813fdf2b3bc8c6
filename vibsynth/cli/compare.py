"""``vibsynth compare A B [C ...]``: the paper's dissimilarity D between recordings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from vibsynth.cli._common import add_basis_argument, basis_from_args, sample_rate
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


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compare",
        help="dissimilarity D between recordings (paper's model: |t1 difference| by default)",
        description="D(x, y) = sum_j w_j |T_xj - T_yj| over the 8 PCA scores. Default weights: the paper's "
        "finding (first component only), so D = |t1_x - t1_y| in t1 units. Two files: one D; more: a matrix.",
    )
    p.add_argument("files", nargs="+", type=Path, metavar="FILE", help="recordings (.wav, .csv/.txt with --rate)")
    p.add_argument("--rate", type=sample_rate, help="sample rate of CSV/TXT recordings (Hz)")
    p.add_argument(
        "--weights",
        type=_weights,
        metavar="W1,W2,...",
        help="weights (e.g. from `vibsynth dissim fit`); default 1,0,0,0,0,0,0,0",
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_basis_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vibsynth.research.dissim import scores_for_files

    if len(args.files) < 2:
        raise ParameterError("compare needs at least two recordings")
    basis = basis_from_args(args)
    weights = check_weights(args.weights if args.weights is not None else PAPER_WEIGHTS, basis.n_components)
    scores = scores_for_files(args.files, basis=basis, fs=args.rate)
    d = dissimilarity_matrix(scores, weights)
    names = [str(f) for f in args.files]
    if args.json:
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
    short = [Path(n).stem[:12] for n in names]
    width = max(8, max(len(s) for s in short))
    print(" " * width + "".join(f"{s:>{width + 1}}" for s in short))
    for s, row in zip(short, d):
        print(f"{s:<{width}}" + "".join(f"{v:>{width + 1}.2f}" for v in row))
    print(f"(D in t1 units with weights {np.array2string(weights, precision=3, separator=',')})")
    return 0
