"""Research tools: dissimilarity ratings, the paper's Lasso fit, and the MDS map.

Reproduces the analysis of the paper's "Predicting dissimilarities from spectral
representation" and "Interpretation of the dissimilarity model" on one's own data:

1. :func:`read_ratings` reads a table of pairwise ratings (CSV ``file_a,file_b,rating``);
2. :func:`scores_for_files` analyses every recording once (8 PCA scores each);
3. :func:`fit_dissimilarity_weights` fits ``rating ~ b0 + sum_j w_j |T_aj - T_bj|`` by
   Lasso, the penalty chosen by 10-fold cross-validation (``LassoCV``), trained on
   80 % of the pairs and tested on the other 20 %, over 100 random splits (seeded);
   it reports the mean and SD of the test R^2, the weights, and the R^2 of each
   component alone and of the first i components (the paper's Fig. 6b as numbers);
4. :func:`mds_map` gives the Fig. 7-style 2-D map (classical MDS of the mean ratings,
   the model's map Procrustes-superimposed on it, correlations with the components).

Decisions
---------
* **Non-negative weights** (``positive=True`` by default): D must remain a distance
  (a negative weight would make pairs that differ *more* on a component rate as
  *more similar*, and breaks the triangle inequality); the paper's model is a
  weighted sum of distances. ``positive=False`` is available for exploration.
* **Standardised features**: each ``d_j`` is divided by its standard deviation over
  the training pairs before the Lasso, so the L1 penalty treats components of very
  different spread (T1 ~ 20, T8 ~ 1 on the default basis) alike; the reported
  weights are mapped back to raw score units (rating per t unit).
* **Repeated pairs** (several participants, or ``a,b`` and ``b,a``) are averaged,
  as the paper analysed the between-participant mean ratings.

scikit-learn is an optional dependency (``pip install 'vibsynth[research]'``) and
is imported only inside the functions that need it.
"""

from __future__ import annotations

import csv
import math
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.dissimilarity import (
    PAPER_WEIGHTS,
    classical_mds,
    dissimilarity_matrix,
    local_distances,
    procrustes,
)
from vibsynth.errors import InputError, MissingDependencyError, ParameterError

__all__ = [
    "MissingDependencyError",
    "require_sklearn",
    "RatingsTable",
    "read_ratings",
    "scores_for_files",
    "DissimilarityFit",
    "fit_dissimilarity_weights",
    "fit_from_ratings",
    "MdsMap",
    "mds_map",
]

_INSTALL_HINT = "pip install 'vibsynth[research]'"


def require_sklearn(what: str = "this analysis") -> Any:
    """Import scikit-learn or raise a clear :class:`MissingDependencyError`.

    Returns
    -------
    sklearn : module
    """
    try:
        import sklearn  # noqa: F401
        import sklearn.linear_model  # noqa: F401
        import sklearn.metrics  # noqa: F401
        import sklearn.model_selection  # noqa: F401
    except ImportError:
        raise MissingDependencyError(f"{what} needs scikit-learn: {_INSTALL_HINT}") from None
    return sklearn


# --------------------------------------------------------------------------- ratings
@dataclass(frozen=True)
class RatingsTable:
    """Pairwise dissimilarity ratings, repeated pairs averaged.

    Attributes
    ----------
    path : pathlib.Path
        The CSV file.
    files : list of pathlib.Path
        Unique recordings in order of first appearance (resolved relative to the CSV's folder).
    pairs : ndarray of int, shape (n_pairs, 2)
        Indices into ``files`` (``i <= j``; ``i == j`` for self-comparisons).
    ratings : ndarray, shape (n_pairs,)
        Mean rating of each unordered pair.
    counts : ndarray of int, shape (n_pairs,)
        How many rows were averaged into each pair.
    n_rows : int
        Data rows read.
    """

    path: Path
    files: list[Path]
    pairs: NDArray[np.int64]
    ratings: NDArray[np.float64]
    counts: NDArray[np.int64]
    n_rows: int

    @property
    def names(self) -> list[str]:
        """Short display names (file stems)."""
        return [f.stem for f in self.files]

    def distinct_pairs(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Pairs of two different files (self-comparisons dropped) and their ratings."""
        keep = self.pairs[:, 0] != self.pairs[:, 1]
        return self.pairs[keep], self.ratings[keep]

    def matrix(self) -> NDArray[np.float64]:
        """Mean-rating matrix for MDS.

        Returns
        -------
        R : ndarray, shape (n_files, n_files)
            Symmetric; diagonal 0 (self-ratings, the task's baseline, are not distances).

        Raises
        ------
        InputError
            A pair of files was never rated (classical MDS needs every pair).
        """
        n = len(self.files)
        r = np.full((n, n), np.nan)
        for (i, j), value in zip(self.pairs, self.ratings):
            r[i, j] = r[j, i] = value
        np.fill_diagonal(r, 0.0)
        missing = np.argwhere(np.isnan(r))
        if missing.size:
            i, j = missing[0]
            raise InputError(
                f"{self.path}: the pair {self.files[i].name}, {self.files[j].name} was never rated; "
                f"the MDS map needs every pair ({missing.shape[0] // 2} missing)"
            )
        return r


_COLUMNS = ("file_a", "file_b", "rating")


def read_ratings(path: str | os.PathLike[str], *, check_files: bool = True) -> RatingsTable:
    """Read a ratings CSV: ``file_a,file_b,rating`` per line.

    A header row naming the columns ``file_a``, ``file_b`` and ``rating`` (any
    order, extra columns ignored) is optional; without it the first three columns
    are taken in that order. Blank lines and lines starting with ``#`` are skipped.
    File names are relative to the CSV's folder (or absolute).

    Parameters
    ----------
    path : path-like
    check_files : bool
        Require every named recording to exist.

    Returns
    -------
    table : RatingsTable

    Raises
    ------
    InputError
        Missing/unreadable file, a row with too few fields, a rating that is not a
        finite number, a recording that does not exist (message names the line), or
        fewer than 3 files.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file" if not p.exists() else f"{p}: is not a file")
    folder = p.parent
    index: dict[Path, int] = {}
    sums: dict[tuple[int, int], list[float]] = {}
    cols = (0, 1, 2)
    n_rows = 0
    header_seen = False
    try:
        with open(p, newline="", encoding="utf-8-sig") as handle:
            for line_no, row in enumerate(csv.reader(handle), start=1):
                fields = [f.strip() for f in row]
                if not any(fields) or fields[0].startswith("#"):
                    continue
                lowered = [f.lower() for f in fields]
                if not header_seen and n_rows == 0 and all(c in lowered for c in _COLUMNS):
                    cols = tuple(lowered.index(c) for c in _COLUMNS)  # type: ignore[assignment]
                    header_seen = True
                    continue
                if len(fields) <= max(cols):
                    raise InputError(f"{p}:{line_no}: expected file_a,file_b,rating, got {len(fields)} field(s)")
                a_name, b_name, rating_text = (fields[c] for c in cols)
                try:
                    rating = float(rating_text)
                except ValueError:
                    if n_rows == 0 and not header_seen:
                        raise InputError(
                            f"{p}:{line_no}: rating {rating_text!r} is not a number "
                            f"(a header row must name the columns file_a,file_b,rating)"
                        ) from None
                    raise InputError(f"{p}:{line_no}: rating {rating_text!r} is not a number") from None
                if not math.isfinite(rating):
                    raise InputError(f"{p}:{line_no}: rating must be finite, got {rating_text!r}")
                ids = []
                for name in (a_name, b_name):
                    if not name:
                        raise InputError(f"{p}:{line_no}: empty file name")
                    fp = Path(name)
                    fp = fp if fp.is_absolute() else folder / fp
                    if fp not in index:
                        if check_files and not fp.is_file():
                            raise InputError(f"{p}:{line_no}: recording {name!r} not found (looked for {fp})")
                        index[fp] = len(index)
                    ids.append(index[fp])
                key = (min(ids), max(ids))
                sums.setdefault(key, []).append(rating)
                n_rows += 1
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a UTF-8 text file") from None
    except csv.Error as exc:
        raise InputError(f"{p}: CSV error: {exc}") from None
    if len(index) < 3:
        raise InputError(f"{p}: need ratings between at least 3 recordings, found {len(index)}")
    keys = sorted(sums)
    return RatingsTable(
        path=p,
        files=list(index),
        pairs=np.array(keys, dtype=np.int64).reshape(-1, 2),
        ratings=np.array([float(np.mean(sums[k])) for k in keys]),
        counts=np.array([len(sums[k]) for k in keys], dtype=np.int64),
        n_rows=n_rows,
    )


def scores_for_files(
    files: Sequence[str | os.PathLike[str]],
    *,
    basis: Any,
    fs: float | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> NDArray[np.float64]:
    """PCA scores of recordings (each analysed once).

    Parameters
    ----------
    files : sequence of path-like
        WAV, or CSV/TXT with ``fs``.
    basis : vibsynth.dsp.basis.Basis
    fs : float, optional
        Sample rate for CSV/TXT recordings.
    progress : callable, optional
        ``progress(i, n, name)`` after each file.

    Returns
    -------
    scores : ndarray, shape (n_files, n_components)

    Raises
    ------
    InputError
        A recording cannot be read or analysed (the message names it).
    """
    from vibsynth.dsp.analysis import analyze
    from vibsynth.formats.recordings import read_recording

    out = []
    for i, f in enumerate(files):
        rec = read_recording(f, fs=fs)
        try:
            out.append(analyze(rec.samples, fs=rec.fs, basis=basis).scores)
        except ParameterError as exc:
            raise InputError(f"{rec.path}: {exc}") from None
        if progress:
            progress(i + 1, len(files), str(f))
    return np.asarray(out, dtype=np.float64)


# --------------------------------------------------------------------------- fit
@dataclass(frozen=True)
class DissimilarityFit:
    """Result of :func:`fit_dissimilarity_weights`.

    Attributes
    ----------
    weights : ndarray, shape (n_components,)
        Weights fitted on all pairs (rating units per score unit); use these.
    intercept : float
        Predicted rating of two identical recordings.
    alpha : float
        Lasso penalty chosen by cross-validation on all pairs.
    r2_mean, r2_sd : float
        Mean and SD of the test R^2 over the random splits (the paper: 0.54, SD 0.11).
    r2_splits : ndarray, shape (n_splits,)
    weights_mean, weights_sd : ndarray, shape (n_components,)
        Weights over the splits.
    selected_fraction : ndarray, shape (n_components,)
        Fraction of splits in which each weight is non-zero.
    r2_single_mean, r2_single_sd : ndarray, shape (n_components,)
        Test R^2 using component j alone (Fig. 6b, red).
    r2_first_mean, r2_first_sd : ndarray, shape (n_components,)
        Test R^2 using components 1..i (Fig. 6b, blue).
    n_pairs, n_splits, n_train, n_test, cv, seed : int
    positive : bool
    solver : str
    """

    weights: NDArray[np.float64]
    intercept: float
    alpha: float
    r2_mean: float
    r2_sd: float
    r2_splits: NDArray[np.float64]
    weights_mean: NDArray[np.float64]
    weights_sd: NDArray[np.float64]
    selected_fraction: NDArray[np.float64]
    r2_single_mean: NDArray[np.float64]
    r2_single_sd: NDArray[np.float64]
    r2_first_mean: NDArray[np.float64]
    r2_first_sd: NDArray[np.float64]
    n_pairs: int
    n_splits: int
    n_train: int
    n_test: int
    cv: int
    seed: int
    positive: bool
    solver: str
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready data."""
        out: dict[str, Any] = {}
        for key, value in self.__dict__.items():
            out[key] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


SOLVERS = ("lars", "cd")
#: Relative spread under which a distance feature is rounding noise (see :func:`_fit_scaled`).
NEGLIGIBLE_SPREAD = 1e-6


def _lasso(x: NDArray[np.float64], y: NDArray[np.float64], *, cv: int, seed: int, positive: bool, solver: str) -> Any:
    from sklearn.linear_model import LassoCV, LassoLarsCV
    from sklearn.model_selection import KFold

    folds = KFold(cv, shuffle=True, random_state=seed)
    if solver == "lars":
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return LassoLarsCV(cv=folds, positive=positive, max_iter=1000).fit(x, y)
        except (ValueError, FloatingPointError):
            # LARS has no path when (with positive=True) no feature correlates positively
            # with the ratings in some fold; coordinate descent handles that case.
            pass
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return LassoCV(cv=folds, positive=positive, max_iter=10000, alphas=50, precompute=True).fit(x, y)


def _fit_scaled(
    x: NDArray[np.float64], y: NDArray[np.float64], *, cv: int, seed: int, positive: bool, solver: str
) -> tuple[NDArray[np.float64], float, float]:
    """Lasso on standardised features; weights mapped back to raw units.

    A feature whose spread is rounding noise next to the others' (below :data:`NEGLIGIBLE_SPREAD`
    of the largest: e.g. T2..T8 of stimuli synthesised as ``M + t1 V1``) gets weight 0: scaled up
    to unit variance, noise would take any weight, and mapped back it would be huge.
    """
    scale = x.std(axis=0)
    keep = scale > NEGLIGIBLE_SPREAD * max(float(scale.max()), 0.0)
    weights = np.zeros(x.shape[1])
    if not keep.any():
        return weights, float(y.mean()), math.nan
    model = _lasso(x[:, keep] / scale[keep], y, cv=cv, seed=seed, positive=positive, solver=solver)
    weights[keep] = np.asarray(model.coef_) / scale[keep]
    return weights, float(model.intercept_), float(model.alpha_)


def _r2(y: NDArray[np.float64], pred: NDArray[np.float64]) -> float:
    ss_res = float(np.sum((y - pred) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")


def fit_dissimilarity_weights(
    distances: ArrayLike,
    ratings: ArrayLike,
    *,
    n_splits: int = 100,
    test_fraction: float = 0.2,
    cv: int = 10,
    seed: int = 0,
    positive: bool = True,
    components: bool = True,
    solver: str = "lars",
) -> DissimilarityFit:
    """Fit the dissimilarity weights the paper's way (Lasso, 10-fold CV, 80/20 x 100).

    Parameters
    ----------
    distances : array_like, shape (n_pairs, n_components)
        Local distances ``|T_a - T_b|`` of each rated pair
        (:func:`vibsynth.dsp.dissimilarity.local_distances`).
    ratings : array_like, shape (n_pairs,)
        Mean dissimilarity rating of each pair.
    n_splits : int
        Random 80/20 splits (the paper: 100).
    test_fraction : float
        Share of pairs held out for testing in each split (the paper: 0.2).
    cv : int
        Folds of the cross-validation choosing the penalty (the paper: 10).
    seed : int
        Seeds the splits and the CV folds: same seed, same numbers.
    positive : bool
        Constrain weights to be >= 0 (default; see the module docstring).
    components : bool
        Also compute the per-component and first-i-components R^2 (Fig. 6b);
        costs ``2 * n_components - 1`` more fits per split.
    solver : {"lars", "cd"}
        ``"lars"``: ``LassoLarsCV`` (the Lasso solved along its exact regularisation
        path; the penalty is chosen among the path's breakpoints by the CV). ``"cd"``:
        ``LassoCV`` (coordinate descent on a grid of 50 penalties). Same model and
        objective; LARS is about 20x faster on 8 features, which makes 100 splits
        with Fig. 6b take seconds instead of minutes.

    Returns
    -------
    fit : DissimilarityFit

    Raises
    ------
    ParameterError
        Shapes disagree, non-finite values, too few pairs for the CV and the split,
        or no variance in the ratings.
    MissingDependencyError
        scikit-learn is not installed.
    """
    require_sklearn("fitting dissimilarity weights")
    x = np.asarray(distances, dtype=np.float64)
    y = np.asarray(ratings, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 1 or x.shape[0] != y.shape[0]:
        raise ParameterError(f"need distances (n_pairs, n_components) and ratings (n_pairs,), got {x.shape}, {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ParameterError("distances and ratings must be finite")
    if not (0.0 < test_fraction < 1.0):
        raise ParameterError(f"test fraction must be in (0, 1), got {test_fraction}")
    if solver not in SOLVERS:
        raise ParameterError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    if n_splits < 1 or cv < 2:
        raise ParameterError(f"need n_splits >= 1 and cv >= 2, got {n_splits}, {cv}")
    n = x.shape[0]
    n_test = max(2, int(round(test_fraction * n)))
    n_train = n - n_test
    if n_train < 2 * cv:
        raise ParameterError(
            f"{n} rated pairs are too few: {cv}-fold cross-validation on an {1 - test_fraction:.0%} training "
            f"set needs at least {int(math.ceil(2 * cv / (1 - test_fraction))) + 1} pairs"
        )
    if np.ptp(y) == 0:
        raise ParameterError("all ratings are equal: nothing to fit")
    k = x.shape[1]
    rng = np.random.default_rng(seed)
    subsets: list[tuple[str, int, list[int]]] = [("all", 0, list(range(k)))]
    if components:
        subsets += [("single", j, [j]) for j in range(k)]
        subsets += [("first", i, list(range(i + 1))) for i in range(1, k - 1)]
    r2: dict[tuple[str, int], list[float]] = {(name, j): [] for name, j, _ in subsets}
    weights_splits = []
    for _split in range(n_splits):
        order = rng.permutation(n)
        test, train = order[:n_test], order[n_test:]
        split_seed = int(rng.integers(2**31 - 1))
        for name, j, cols in subsets:
            w, b, _ = _fit_scaled(x[train][:, cols], y[train], cv=cv, seed=split_seed, positive=positive, solver=solver)
            r2[(name, j)].append(_r2(y[test], x[test][:, cols] @ w + b))
            if name == "all":
                weights_splits.append(w)
    w_all, b_all, alpha = _fit_scaled(x, y, cv=cv, seed=seed, positive=positive, solver=solver)
    ws = np.asarray(weights_splits)
    main = np.asarray(r2[("all", 0)])

    def stats(name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        rows = []
        for j in range(k):
            key = (
                ("all", 0)
                if (name == "first" and j == k - 1)
                else ("single", 0)
                if (name == "first" and j == 0)
                else (name, j)
            )
            rows.append(np.asarray(r2[key]))
        arr = np.asarray(rows)
        return np.nanmean(arr, axis=1), np.nanstd(arr, axis=1)

    if components:
        single_mean, single_sd = stats("single")
        first_mean, first_sd = stats("first")
    else:
        single_mean = single_sd = first_mean = first_sd = np.full(k, np.nan)
    return DissimilarityFit(
        weights=w_all,
        intercept=b_all,
        alpha=alpha,
        r2_mean=float(np.nanmean(main)),
        r2_sd=float(np.nanstd(main)),
        r2_splits=main,
        weights_mean=ws.mean(axis=0),
        weights_sd=ws.std(axis=0),
        selected_fraction=(ws > 0 if positive else ws != 0).mean(axis=0),
        r2_single_mean=single_mean,
        r2_single_sd=single_sd,
        r2_first_mean=first_mean,
        r2_first_sd=first_sd,
        n_pairs=n,
        n_splits=int(n_splits),
        n_train=n_train,
        n_test=n_test,
        cv=int(cv),
        seed=int(seed),
        positive=bool(positive),
        solver=solver,
    )


def fit_from_ratings(
    table: RatingsTable,
    scores: ArrayLike,
    *,
    include_self_pairs: bool = True,
    **kwargs: Any,
) -> DissimilarityFit:
    """:func:`fit_dissimilarity_weights` on a ratings table and the files' scores.

    Parameters
    ----------
    table : RatingsTable
    scores : array_like, shape (n_files, n_components)
        Scores of ``table.files`` in that order (:func:`scores_for_files`).
    include_self_pairs : bool
        Keep self-comparisons (distance 0; the paper presented them as the baseline).
    **kwargs
        Passed on (``n_splits``, ``seed``, ``cv``, ``positive``, ...).
    """
    s = np.asarray(scores, dtype=np.float64)
    if s.ndim != 2 or s.shape[0] != len(table.files):
        raise ParameterError(f"need scores for {len(table.files)} files, got shape {s.shape}")
    pairs, ratings = (table.pairs, table.ratings) if include_self_pairs else table.distinct_pairs()
    d = local_distances(s[pairs[:, 0]], s[pairs[:, 1]])
    return fit_dissimilarity_weights(d, ratings, **kwargs)


# --------------------------------------------------------------------------- MDS map
@dataclass(frozen=True)
class MdsMap:
    """Fig. 7-style perceptual map.

    Attributes
    ----------
    names : list of str
    rated : ndarray, shape (n_items, 2)
        Classical MDS of the mean ratings.
    predicted : ndarray, shape (n_items, 2)
        Classical MDS of the model's D, Procrustes-superimposed on ``rated``.
    procrustes_rms : float
        RMS distance between rated and predicted positions (rating units).
    component_r : ndarray, shape (n_components, 2)
        Pearson r of each score T_j with each MDS dimension (the arrow of V1 is row 0).
    eigenvalues : ndarray, shape (n_items,)
        Of the rated MDS (how much the 2-D map shows).
    """

    names: list[str]
    rated: NDArray[np.float64]
    predicted: NDArray[np.float64]
    procrustes_rms: float
    component_r: NDArray[np.float64]
    eigenvalues: NDArray[np.float64]


def _pearson(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def mds_map(table: RatingsTable, scores: ArrayLike, *, weights: ArrayLike = PAPER_WEIGHTS) -> MdsMap:
    """Classical MDS of the rated and of the predicted dissimilarities.

    Parameters
    ----------
    table : RatingsTable
        Must rate every pair of files.
    scores : array_like, shape (n_files, n_components)
    weights : array_like, shape (n_components,)
        Model weights (e.g. ``DissimilarityFit.weights``); the default is the paper's.

    Returns
    -------
    map : MdsMap
    """
    s = np.asarray(scores, dtype=np.float64)
    rated, eig = classical_mds(table.matrix(), 2, return_eigenvalues=True)
    model = classical_mds(dissimilarity_matrix(s, weights), 2)
    aligned, rms = procrustes(rated, model)
    r = np.array([[_pearson(s[:, j], rated[:, d]) for d in range(2)] for j in range(s.shape[1])])
    # Orient the first axis like t1 (MDS signs are arbitrary).
    if np.isfinite(r[0, 0]) and r[0, 0] < 0:
        rated[:, 0] *= -1
        aligned[:, 0] *= -1
        r[:, 0] *= -1
    return MdsMap(
        names=table.names,
        rated=rated,
        predicted=aligned,
        procrustes_rms=rms,
        component_r=r,
        eigenvalues=eig,
    )
