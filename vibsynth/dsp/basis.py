"""Spectral basis: mean spectrum M and principal components V1..V8 of dB band spectra.

Normalisation (why the mean dB is removed)
------------------------------------------
Each 30-band spectrum is taken in dB and its mean across bands is subtracted
before the PCA, so PC1 describes *shape* (the high/low balance), not loudness.
This normalisation is idempotent: a spectrum ``M + t V1 + c`` (any level ``c``)
normalises back to ``M + t V1``, because M has zero band-mean and every component
is orthogonal to the constant vector (all normalised spectra live in the
zero-mean subspace). So a synthesized ``M + t V1`` re-analyses to exactly ``t``.

Sign convention: positive ``t1`` = more high-frequency energy (V1 correlates
positively with log-frequency). Other components have their largest-magnitude
entry positive, so a refit is reproducible.

Balance knob units: 0 = M (``t1 = 0``), +1 = the 98th percentile of ``t1`` over
the basis' database, -1 = the 2nd percentile; piecewise linear on each side, so
values beyond +-1 are legal and simply further out.

No I/O here: :meth:`Basis.to_dict` / :meth:`Basis.from_dict` give plain data that
:mod:`vibsynth.formats` writes and reads as YAML.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.filterbank import BAND_CENTRES_HZ, BAND_ORDER, bandpass_response
from vibsynth.errors import ParameterError

__all__ = [
    "N_COMPONENTS",
    "BASIS_FORMAT",
    "Basis",
    "to_db",
    "normalise_db",
    "fit_basis",
    "band_powers_from_psd",
]

N_COMPONENTS = 8
BASIS_FORMAT = 1
_PERCENTILES = (2.0, 50.0, 98.0)
_DECIMALS = 8  # stored precision; the id hashes the stored numbers


def to_db(power: ArrayLike, *, floor: float = 1e-30) -> NDArray[np.float64]:
    """Power to dB, floored so that empty bands stay finite.

    Parameters
    ----------
    power : array_like, shape (...,)

    Returns
    -------
    db : ndarray, shape (...,)
    """
    return 10.0 * np.log10(np.maximum(np.asarray(power, dtype=np.float64), floor))


def normalise_db(band_db: ArrayLike) -> NDArray[np.float64]:
    """Remove each spectrum's level: subtract its mean dB across bands.

    Parameters
    ----------
    band_db : array_like, shape (..., n_bands)

    Returns
    -------
    shape_db : ndarray, shape (..., n_bands)
        Zero mean along the last axis.
    """
    arr = np.asarray(band_db, dtype=np.float64)
    return np.asarray(arr - arr.mean(axis=-1, keepdims=True), dtype=np.float64)


@dataclass(frozen=True)
class Basis:
    """A spectral basis fitted by PCA over level-normalised dB band spectra.

    Attributes
    ----------
    centres_hz : ndarray, shape (n_bands,)
        Band centre frequencies.
    filter_order : int
        Butterworth order of the filter bank the basis was fitted with.
    mean_db : ndarray, shape (n_bands,)
        Mean normalised spectrum M (zero band-mean).
    components : ndarray, shape (n_components, n_bands)
        Orthonormal components V1..Vn (rows).
    explained_variance_ratio : ndarray, shape (n_components,)
        Share of the total variance of each component.
    t1_percentiles : dict
        ``{2.0: p2, 50.0: p50, 98.0: p98}`` of t1 over the database.
    t1_min, t1_max : float
        Range of t1 over the database.
    score_std : ndarray, shape (n_components,)
        Standard deviation of each score over the database.
    n_spectra : int
        Number of spectra fitted.
    provenance : dict
        Source, method and citation (free-form strings).
    """

    centres_hz: NDArray[np.float64]
    filter_order: int
    mean_db: NDArray[np.float64]
    components: NDArray[np.float64]
    explained_variance_ratio: NDArray[np.float64]
    t1_percentiles: Mapping[float, float]
    t1_min: float
    t1_max: float
    score_std: NDArray[np.float64]
    n_spectra: int
    provenance: Mapping[str, Any] = field(default_factory=dict)

    # ----------------------------------------------------------------- derived
    @property
    def n_bands(self) -> int:
        return int(self.centres_hz.size)

    @property
    def n_components(self) -> int:
        return int(self.components.shape[0])

    @property
    def v1(self) -> NDArray[np.float64]:
        """First component, shape (n_bands,)."""
        return np.asarray(self.components[0], dtype=np.float64)

    @property
    def id(self) -> str:
        """Short content hash (12 hex digits) of the numbers that define the basis."""
        payload = json.dumps({k: v for k, v in self._numbers().items()}, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(payload.encode()).hexdigest()[:12]

    # ----------------------------------------------------------------- scores
    def scores(self, band_db: ArrayLike) -> NDArray[np.float64]:
        """PCA scores of dB band spectra (level removed first).

        Parameters
        ----------
        band_db : array_like, shape (..., n_bands)

        Returns
        -------
        scores : ndarray, shape (..., n_components)
        """
        arr = np.asarray(band_db, dtype=np.float64)
        if arr.shape[-1] != self.n_bands:
            raise ParameterError(f"expected {self.n_bands} bands, got {arr.shape[-1]}")
        return np.asarray((normalise_db(arr) - self.mean_db) @ self.components.T, dtype=np.float64)

    def reconstruct(self, scores: ArrayLike, *, components: slice | None = None) -> NDArray[np.float64]:
        """Normalised dB spectrum ``M + sum_i t_i V_i`` over the chosen components.

        Parameters
        ----------
        scores : array_like, shape (..., n_components)
        components : slice, optional
            Which components to use (``slice(0, 1)`` = S1, ``slice(1, None)`` = S2:8).

        Returns
        -------
        band_db : ndarray, shape (..., n_bands)
        """
        t = np.asarray(scores, dtype=np.float64)
        sl = components if components is not None else slice(None)
        return self.mean_db + t[..., sl] @ self.components[sl]

    # ----------------------------------------------------------------- balance
    def balance_from_t1(self, t1: ArrayLike) -> NDArray[np.float64]:
        """Balance knob units from raw t1 (0 = M, +-1 = 98th/2nd percentile).

        Parameters
        ----------
        t1 : array_like, shape (...,)

        Returns
        -------
        balance : ndarray, shape (...,)
        """
        t = np.asarray(t1, dtype=np.float64)
        return np.where(t >= 0, t / self._p98, t / -self._p2)

    def t1_from_balance(self, balance: ArrayLike) -> NDArray[np.float64]:
        """Raw t1 from balance knob units (inverse of :meth:`balance_from_t1`).

        Parameters
        ----------
        balance : array_like, shape (...,)

        Returns
        -------
        t1 : ndarray, shape (...,)
        """
        b = np.asarray(balance, dtype=np.float64)
        if not np.all(np.isfinite(b)):
            raise ParameterError("balance must be finite")
        return np.where(b >= 0, b * self._p98, b * -self._p2)

    def spectrum_for_balance(self, balance: ArrayLike) -> NDArray[np.float64]:
        """Normalised dB spectra ``M + t1(b) V1``.

        Parameters
        ----------
        balance : array_like, shape (...,)

        Returns
        -------
        band_db : ndarray, shape (..., n_bands)
        """
        t1 = self.t1_from_balance(balance)
        return self.mean_db + t1[..., np.newaxis] * self.v1

    @property
    def _p98(self) -> float:
        return float(self.t1_percentiles[98.0])

    @property
    def _p2(self) -> float:
        return float(self.t1_percentiles[2.0])

    def t1_in_database_range(self, t1: float) -> bool:
        """Whether a t1 lies within the range spanned by the basis' database."""
        return bool(self.t1_min <= t1 <= self.t1_max)

    # ----------------------------------------------------------------- (de)serialisation
    def _numbers(self) -> dict[str, Any]:
        def r(a: Any) -> Any:
            return np.round(np.asarray(a, dtype=np.float64), _DECIMALS).tolist()

        return {
            "centres_hz": r(self.centres_hz),
            "filter_order": int(self.filter_order),
            "mean_db": r(self.mean_db),
            "components": r(self.components),
            "explained_variance_ratio": r(self.explained_variance_ratio),
            "t1_percentiles": {f"p{p:g}": r(v) for p, v in sorted(self.t1_percentiles.items())},
            "t1_min": r(self.t1_min),
            "t1_max": r(self.t1_max),
            "score_std": r(self.score_std),
            "n_spectra": int(self.n_spectra),
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain data (lists, floats, strings) for YAML; numbers rounded to 8 decimals."""
        return {"format": BASIS_FORMAT, "id": self.id, **self._numbers(), "provenance": dict(self.provenance)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Basis:
        """Build a basis from :meth:`to_dict` data, validating shapes and values.

        Raises
        ------
        ParameterError
            Missing keys, wrong shapes, non-finite numbers or a non-orthonormal V.
        """
        try:
            if int(data.get("format", BASIS_FORMAT)) != BASIS_FORMAT:
                raise ParameterError(f"basis format {data.get('format')} is not supported (expected {BASIS_FORMAT})")
            centres = np.asarray(data["centres_hz"], dtype=np.float64)
            mean_db = np.asarray(data["mean_db"], dtype=np.float64)
            components = np.asarray(data["components"], dtype=np.float64)
            evr = np.asarray(data["explained_variance_ratio"], dtype=np.float64)
            pct = {float(str(k).lstrip("p")): float(v) for k, v in dict(data["t1_percentiles"]).items()}
            basis = cls(
                centres_hz=centres,
                filter_order=int(data.get("filter_order", BAND_ORDER)),
                mean_db=mean_db,
                components=components,
                explained_variance_ratio=evr,
                t1_percentiles=pct,
                t1_min=float(data["t1_min"]),
                t1_max=float(data["t1_max"]),
                score_std=np.asarray(data["score_std"], dtype=np.float64),
                n_spectra=int(data["n_spectra"]),
                provenance=dict(data.get("provenance") or {}),
            )
        except KeyError as exc:
            raise ParameterError(f"basis is missing the key {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ParameterError):
                raise
            raise ParameterError(f"basis has a malformed value: {exc}") from None
        basis._validate()
        return basis

    def _validate(self) -> None:
        n = self.centres_hz.size
        if self.centres_hz.ndim != 1 or n < 2 or np.any(np.diff(self.centres_hz) <= 0):
            raise ParameterError("basis centres_hz must be an increasing list of >= 2 frequencies")
        if self.mean_db.shape != (n,):
            raise ParameterError(f"basis mean_db must have {n} values, has {self.mean_db.size}")
        if self.components.ndim != 2 or self.components.shape[1] != n or self.components.shape[0] < 1:
            raise ParameterError(f"basis components must be a (k, {n}) matrix, got {self.components.shape}")
        k = self.components.shape[0]
        for name, arr in (("explained_variance_ratio", self.explained_variance_ratio), ("score_std", self.score_std)):
            if arr.shape != (k,):
                raise ParameterError(f"basis {name} must have {k} values")
        numbers = [self.centres_hz, self.mean_db, self.components, self.explained_variance_ratio, self.score_std]
        if not all(np.all(np.isfinite(a)) for a in numbers):
            raise ParameterError("basis contains NaN or infinite numbers")
        if not np.allclose(self.components @ self.components.T, np.eye(k), atol=1e-5):
            raise ParameterError("basis components are not orthonormal")
        if not (self._p2 < 0 < self._p98):
            raise ParameterError("basis t1 percentiles must satisfy p2 < 0 < p98")


def band_powers_from_psd(
    freqs_hz: ArrayLike,
    psd: ArrayLike,
    *,
    centres: ArrayLike = BAND_CENTRES_HZ,
    order: int = BAND_ORDER,
    oversample: int = 8,
) -> NDArray[np.float64]:
    """Band powers of one-sided PSDs given on a (log-spaced) frequency grid.

    The PSD is interpolated linearly in log-log on a grid ``oversample`` times finer,
    then ``integral |H_k(f)|^2 PSD(f) df`` is taken by the trapezoid rule. The result
    has the unit of the mean square of the signal, as :func:`band_powers` gives.

    Parameters
    ----------
    freqs_hz : array_like, shape (n_freqs,)
        Increasing, positive frequencies.
    psd : array_like, shape (..., n_freqs)
        One-sided PSD (unit^2 / Hz), positive.
    centres : array_like, shape (n_bands,)
    order : int
    oversample : int

    Returns
    -------
    band_power : ndarray, shape (..., n_bands)
    """
    f = np.asarray(freqs_hz, dtype=np.float64)
    p = np.asarray(psd, dtype=np.float64)
    if f.ndim != 1 or f.size < 2 or np.any(np.diff(f) <= 0) or f[0] <= 0:
        raise ParameterError("PSD frequencies must be increasing and positive")
    if p.shape[-1] != f.size:
        raise ParameterError(f"PSD has {p.shape[-1]} columns but {f.size} frequencies")
    if not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ParameterError("PSD values must be finite and positive")
    log_f = np.log(f)
    fine_log_f = np.linspace(log_f[0], log_f[-1], (f.size - 1) * oversample + 1)
    fine_f = np.exp(fine_log_f)
    flat = np.log(p.reshape(-1, f.size))
    fine_psd = np.exp(np.stack([np.interp(fine_log_f, log_f, row) for row in flat]))
    # Trapezoid rule as a weight per grid point, so the integral is one matrix product.
    trapezoid = np.zeros_like(fine_f)
    trapezoid[1:] += 0.5 * np.diff(fine_f)
    trapezoid[:-1] += 0.5 * np.diff(fine_f)
    weighted = bandpass_response(fine_f, centres=centres, order=order) * trapezoid  # (bands, fine)
    powers = fine_psd @ weighted.T
    return np.asarray(powers.reshape(p.shape[:-1] + (np.asarray(centres).size,)), dtype=np.float64)


def _orient(components: NDArray[np.float64], centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fix each component's sign: V1 rises with log-frequency, others have their largest entry positive."""
    out = components.copy()
    tilt = np.log(centres) - np.log(centres).mean()
    if out[0] @ tilt < 0:
        out[0] = -out[0]
    for i in range(1, out.shape[0]):
        if out[i][np.argmax(np.abs(out[i]))] < 0:
            out[i] = -out[i]
    return np.asarray(out, dtype=np.float64)


def fit_basis(
    band_db: ArrayLike,
    *,
    n_components: int = N_COMPONENTS,
    centres: ArrayLike = BAND_CENTRES_HZ,
    order: int = BAND_ORDER,
    provenance: Mapping[str, Any] | None = None,
) -> Basis:
    """Fit a basis by PCA over level-normalised dB band spectra.

    Parameters
    ----------
    band_db : array_like, shape (n_spectra, n_bands)
        Band powers in dB (each row one recording or PSD); every row weighs the same.
    n_components : int
        Components to keep (the paper: 8, about 95 % of the variance).
    centres : array_like, shape (n_bands,)
    order : int
    provenance : mapping, optional
        Stored as is.

    Returns
    -------
    basis : Basis
    """
    x = np.asarray(band_db, dtype=np.float64)
    centres = np.asarray(centres, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != centres.size:
        raise ParameterError(f"expected band spectra of shape (n, {centres.size}), got {x.shape}")
    if x.shape[0] <= n_components:
        raise ParameterError(
            f"need more than {n_components} spectra to fit {n_components} components, got {x.shape[0]}"
        )
    if not np.all(np.isfinite(x)):
        raise ParameterError("band spectra contain NaN or infinite values")
    shapes = normalise_db(x)
    mean = shapes.mean(axis=0)
    centred = shapes - mean
    # SVD of the centred data: rows of vt are the principal directions.
    _, singular, vt = np.linalg.svd(centred, full_matrices=False)
    variance = singular**2
    components = _orient(vt[:n_components], centres)
    scores = centred @ components.T
    t1 = scores[:, 0]
    return Basis(
        centres_hz=centres,
        filter_order=int(order),
        mean_db=mean,
        components=components,
        explained_variance_ratio=variance[:n_components] / variance.sum(),
        t1_percentiles={p: float(np.percentile(t1, p)) for p in _PERCENTILES},
        t1_min=float(t1.min()),
        t1_max=float(t1.max()),
        score_std=scores.std(axis=0),
        n_spectra=int(x.shape[0]),
        provenance=dict(provenance or {}),
    )
