"""The paper's dissimilarity model and classical MDS.

Model (paper, "Predicting dissimilarities from spectral representation")
------------------------------------------------------------------------
Two vibrations ``x`` and ``y`` are compared through their PCA scores
``T = V P`` (``P``: level-normalised 30-band dB spectrum, ``V``: the basis'
8 components):

.. math:: D(x, y) = \\sum_{j=1}^{8} w_j \\, |T_{xj} - T_{yj}|.

With non-negative weights D is a pseudo-metric on the score space: ``D(x, x) = 0``,
symmetric, and it obeys the triangle inequality (a weighted L1 distance).

Default weights: the paper's finding (Fig. 6b) that only the first component
matters, ``w = [1, 0, ..., 0]``, so by default ``D = |t1_x - t1_y|`` in t1 units
(dB of the level-normalised spectrum projected on the unit vector V1; the default
basis spans about -40..+40 t1 between its 2nd and 98th percentile). Weights
fitted to ratings (:func:`vibsynth.research.dissim.fit_dissimilarity_weights`) put D on
the rating scale instead (plus an intercept, the rating of identical pairs).

Classical (Torgerson) MDS places items in a low-dimensional space whose Euclidean
distances approximate a dissimilarity matrix (paper, Fig. 7); :func:`procrustes`
superimposes two such maps (translation, rotation/reflection, uniform scale).

No I/O here: arrays in, arrays out.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.errors import ParameterError

__all__ = [
    "PAPER_WEIGHTS",
    "check_weights",
    "local_distances",
    "dissimilarity",
    "dissimilarity_matrix",
    "classical_mds",
    "procrustes",
]

#: The paper's finding: only the first PCA component predicts dissimilarity.
PAPER_WEIGHTS: NDArray[np.float64] = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
PAPER_WEIGHTS.setflags(write=False)


def check_weights(weights: ArrayLike, n_components: int) -> NDArray[np.float64]:
    """Validate a weight vector.

    Parameters
    ----------
    weights : array_like, shape (n_components,) or shorter
        Non-negative, finite. A shorter vector is padded with zeros (weights for
        the first components only); a longer one is an error.
    n_components : int
        Number of score components it will be applied to.

    Returns
    -------
    weights : ndarray, shape (n_components,)

    Raises
    ------
    ParameterError
        Not 1-D, too long, negative or non-finite entries.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise ParameterError(f"weights must be a non-empty 1-D vector, got shape {w.shape}")
    if w.size > n_components:
        raise ParameterError(f"got {w.size} weights for {n_components} score components")
    if not np.all(np.isfinite(w)):
        raise ParameterError("weights must be finite")
    if np.any(w < 0):
        raise ParameterError("weights must be non-negative (a negative weight breaks the metric properties of D)")
    if w.size < n_components:
        w = np.concatenate([w, np.zeros(n_components - w.size)])
    return w


def _check_scores(scores: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(scores, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] < 1:
        raise ParameterError(f"{name} must have shape (..., n_components), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} contains NaN or infinite values")
    return arr


def local_distances(scores_x: ArrayLike, scores_y: ArrayLike) -> NDArray[np.float64]:
    """Per-component distances ``d_j = |T_xj - T_yj|`` (the regression's features).

    Parameters
    ----------
    scores_x, scores_y : array_like, shape (..., n_components)
        Broadcast against each other.

    Returns
    -------
    d : ndarray, shape (..., n_components)
    """
    x = _check_scores(scores_x, "scores_x")
    y = _check_scores(scores_y, "scores_y")
    if x.shape[-1] != y.shape[-1]:
        raise ParameterError(f"scores have {x.shape[-1]} and {y.shape[-1]} components")
    try:
        return np.abs(x - y)
    except ValueError:
        raise ParameterError(f"score shapes {x.shape} and {y.shape} do not broadcast") from None


def dissimilarity(
    scores_x: ArrayLike, scores_y: ArrayLike, weights: ArrayLike = PAPER_WEIGHTS
) -> NDArray[np.float64] | float:
    """The paper's dissimilarity ``D = sum_j w_j |T_xj - T_yj|``.

    Parameters
    ----------
    scores_x, scores_y : array_like, shape (..., n_components)
        PCA scores (e.g. ``Analysis.scores`` or ``Basis.scores(band_db)``); leading
        axes broadcast.
    weights : array_like, shape (n_components,)
        Non-negative; default :data:`PAPER_WEIGHTS` (first component only). A
        shorter vector weighs the first components only.

    Returns
    -------
    D : float or ndarray, shape (...)
        A float for two single score vectors.

    Examples
    --------
    >>> dissimilarity([10.0, 3.0], [4.0, -1.0], weights=[1.0, 0.5])
    8.0
    """
    d = local_distances(scores_x, scores_y)
    w = check_weights(weights, d.shape[-1])
    out = d @ w
    return float(out) if np.ndim(out) == 0 else out


def dissimilarity_matrix(scores: ArrayLike, weights: ArrayLike = PAPER_WEIGHTS) -> NDArray[np.float64]:
    """D between every pair of items.

    Parameters
    ----------
    scores : array_like, shape (n_items, n_components)
    weights : array_like, shape (n_components,)

    Returns
    -------
    D : ndarray, shape (n_items, n_items)
        Symmetric, zero diagonal.
    """
    s = _check_scores(scores, "scores")
    if s.ndim != 2:
        raise ParameterError(f"scores must have shape (n_items, n_components), got {s.shape}")
    return np.asarray(dissimilarity(s[:, np.newaxis, :], s[np.newaxis, :, :], weights))


def _check_square(d: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(d, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] < 2:
        raise ParameterError(f"dissimilarity matrix must be square with >= 2 items, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError("dissimilarity matrix contains NaN or infinite values")
    if not np.allclose(arr, arr.T, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(arr).max()))):
        raise ParameterError("dissimilarity matrix must be symmetric")
    return arr


def classical_mds(
    D: ArrayLike, n_components: int = 2, *, return_eigenvalues: bool = False
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Classical (Torgerson) multidimensional scaling.

    ``B = -1/2 J D^2 J`` (``J`` the centring matrix) is eigen-decomposed; the
    coordinates are the leading eigenvectors scaled by ``sqrt(eigenvalue)``. For a
    Euclidean distance matrix this recovers the configuration up to a rigid motion.
    The diagonal is ignored (taken as 0). Each axis' sign is fixed so that its
    largest-magnitude coordinate is positive (reproducible output).

    Parameters
    ----------
    D : array_like, shape (n_items, n_items)
        Symmetric dissimilarities.
    n_components : int
        Output dimensions (1 <= n_components < n_items).
    return_eigenvalues : bool
        Also return all eigenvalues of ``B`` (descending), e.g. to judge how much
        of the structure the map shows (negative ones: non-Euclidean part).

    Returns
    -------
    coordinates : ndarray, shape (n_items, n_components)
        Centred. Axes whose eigenvalue is not positive are 0.
    eigenvalues : ndarray, shape (n_items,)
        Only with ``return_eigenvalues``.
    """
    d = _check_square(D).copy()
    n = d.shape[0]
    if not (1 <= int(n_components) < n):
        raise ParameterError(f"n_components must be in 1..{n - 1}, got {n_components}")
    np.fill_diagonal(d, 0.0)
    j = np.eye(n) - np.full((n, n), 1.0 / n)
    b = -0.5 * j @ (d * d) @ j
    values, vectors = np.linalg.eigh((b + b.T) / 2)
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order]
    k = int(n_components)
    coords = vectors[:, :k] * np.sqrt(np.maximum(values[:k], 0.0))
    for i in range(k):
        if coords[np.argmax(np.abs(coords[:, i])), i] < 0:
            coords[:, i] = -coords[:, i]
    return (coords, values) if return_eigenvalues else coords


def procrustes(reference: ArrayLike, moving: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """Superimpose ``moving`` on ``reference`` by translation, rotation/reflection and uniform scale.

    Parameters
    ----------
    reference, moving : array_like, shape (n_items, n_dims)

    Returns
    -------
    aligned : ndarray, shape (n_items, n_dims)
        ``moving`` transformed to best match ``reference`` in least squares.
    rms_error : float
        Root-mean-square distance between matching points after alignment.
    """
    a = np.asarray(reference, dtype=np.float64)
    m = np.asarray(moving, dtype=np.float64)
    if a.ndim != 2 or a.shape != m.shape:
        raise ParameterError(f"procrustes needs two (n_items, n_dims) arrays of one shape, got {a.shape}, {m.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(m))):
        raise ParameterError("procrustes inputs contain NaN or infinite values")
    a_mean, m_mean = a.mean(axis=0), m.mean(axis=0)
    a0, m0 = a - a_mean, m - m_mean
    norm = float(np.sum(m0 * m0))
    if norm == 0.0:
        aligned = np.broadcast_to(a_mean, a.shape).copy()
    else:
        u, s, vt = np.linalg.svd(m0.T @ a0)
        rotation = u @ vt
        scale = float(s.sum()) / norm
        aligned = scale * m0 @ rotation + a_mean
    return aligned, float(np.sqrt(np.mean(np.sum((aligned - a) ** 2, axis=1))))
