r"""Spatial textures: how far a touch source reaches on a layout of actuators, and how sources mix.

Roll-off (a power weight :math:`w(d) \in [0, 1]` of the distance ``d`` from a source to an
actuator, for a source of radius ``r``):

* ``linear``: :math:`w = \max(0, 1 - d/r)`;
* ``smooth`` (raised cosine): :math:`w = \tfrac12 (1 + \cos(\pi d / r))` inside ``r``, 0 outside;
* ``inverse-square``: :math:`w = 1 / (1 + (d/r)^2)`, no cut-off;
* ``phantom``: energy-preserving panning between the two or three actuators around the source
  (the "tactile brush" energy model: the squared amplitudes add up to the source's, so the power
  weights sum to 1). The layout is triangulated once (Delaunay, in its best-fitting plane; a
  layout on a line is cut into segments); a source inside a triangle gets its barycentric
  coordinates as power weights, a source outside the layout is panned along the nearest edge of
  its outline, between that edge's two ends. Both are continuous in the source's position.
  The radius plays no part.

Perceptual mixing (the paper's model: a noisy texture is felt through its 80-200 Hz band level
and its high/low balance). Each source stands for its 30-band spectrum ``M + t1(b) V1`` scaled
to its intensity level; an actuator receives the sum of the sources' *linear* band powers and
80-200 Hz band powers, each times the source's weight there. The sum is analysed as the DSP core
analyses a recording: its level is ``10 log10`` of the summed 80-200 Hz power, its balance the
projection of its normalised dB spectrum on V1 (:meth:`vibsynth.dsp.basis.Basis.scores`). So a
single source at weight 1 plays exactly its own knobs, and at weight ``w`` its level lies
``10 log10(w)`` dB lower with the same balance.

No I/O here: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.basis import Basis, to_db
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import ParameterError

__all__ = [
    "ROLLOFFS",
    "DISTANCE_ROLLOFFS",
    "check_rolloff",
    "distances",
    "rolloff_weights",
    "PhantomPanner",
    "SpatialLayout",
    "TextureSpectra",
    "Mix",
    "mix_sources",
]

#: Roll-off laws, in the order documented.
ROLLOFFS = ("linear", "smooth", "inverse-square", "phantom")
#: The laws that are a function of the distance alone.
DISTANCE_ROLLOFFS = ("linear", "smooth", "inverse-square")

#: Grid step (knob units) of the tabulated level offsets of :class:`TextureSpectra`.
SPECTRA_STEP = 0.01
#: FFT grid of the shaper that relates a spectrum's band powers to its 80-200 Hz level
#: (1 Hz bins; the responses are analog, so the result does not depend on it).
_SHAPER_FS = 4800.0
_SHAPER_SAMPLES = 4800


def check_rolloff(name: str) -> str:
    """Validate a roll-off law name; return it.

    Raises
    ------
    ParameterError
        For a name not in :data:`ROLLOFFS`.
    """
    if name not in ROLLOFFS:
        raise ParameterError(f"unknown roll-off {name!r}; choose one of {', '.join(ROLLOFFS)}")
    return name


def _points(positions: ArrayLike, what: str) -> NDArray[np.float64]:
    arr = np.asarray(positions, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[np.newaxis]
    if arr.ndim != 2 or arr.shape[1] not in (2, 3) or arr.shape[0] < 1:
        raise ParameterError(f"{what} must be (n, 2) or (n, 3) coordinates, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{what} must be finite")
    if arr.shape[1] == 2:
        arr = np.concatenate([arr, np.zeros((arr.shape[0], 1))], axis=1)
    return arr


def distances(actuators: ArrayLike, point: ArrayLike) -> NDArray[np.float64]:
    """Euclidean distances from a point to each actuator.

    Parameters
    ----------
    actuators : array_like, shape (n_actuators, 3) or (n_actuators, 2)
        Positions in metres (z = 0 when left out).
    point : array_like, shape (3,) or (2,)

    Returns
    -------
    d : ndarray, shape (n_actuators,)
    """
    return np.asarray(
        np.linalg.norm(_points(actuators, "actuators") - _points(point, "point")[0], axis=1), dtype=np.float64
    )


def rolloff_weights(law: str, d: ArrayLike, radius: float) -> NDArray[np.float64]:
    """Power weights of a distance law (``linear``, ``smooth`` or ``inverse-square``).

    Parameters
    ----------
    law : str
        One of :data:`DISTANCE_ROLLOFFS`.
    d : array_like, shape (n,)
        Distances in metres (>= 0).
    radius : float
        The source's radius in metres (> 0).

    Returns
    -------
    w : ndarray, shape (n,)
        In [0, 1]; 1 at ``d = 0``.
    """
    if law not in DISTANCE_ROLLOFFS:
        raise ParameterError(f"roll-off {law!r} is not a law of the distance ({', '.join(DISTANCE_ROLLOFFS)})")
    if not (math.isfinite(radius) and radius > 0):
        raise ParameterError(f"radius must be a finite number > 0 m, got {radius!r}")
    x = np.asarray(d, dtype=np.float64) / radius
    if law == "linear":
        return np.asarray(np.clip(1.0 - x, 0.0, 1.0), dtype=np.float64)
    if law == "smooth":
        return np.asarray(np.where(x < 1.0, 0.5 * (1.0 + np.cos(np.pi * np.minimum(x, 1.0))), 0.0), dtype=np.float64)
    return np.asarray(1.0 / (1.0 + x * x), dtype=np.float64)


class PhantomPanner:
    """Energy-preserving panning over a layout (the ``phantom`` roll-off).

    The layout is projected on its best-fitting line or plane (principal axes of the
    positions), and cut into segments (a line) or Delaunay triangles (a plane) once.

    Parameters
    ----------
    actuators : array_like, shape (n_actuators, 3) or (n_actuators, 2)
    """

    def __init__(self, actuators: ArrayLike) -> None:
        points = _points(actuators, "actuators")
        self.n = int(points.shape[0])
        self._origin = points.mean(axis=0)
        centred = points - self._origin
        _, singular, vt = np.linalg.svd(centred, full_matrices=False)
        scale = float(singular[0]) if singular.size else 0.0
        tolerance = 1e-9 * max(scale, 1e-12)
        self.dims = 0 if self.n == 1 or scale <= 1e-12 else (1 if singular.size < 2 or singular[1] <= tolerance else 2)
        self._axes = vt[: max(self.dims, 1)]
        self._coords = centred @ self._axes.T  # (n, dims)
        self._tri: Any = None
        if self.dims == 2:
            self._tri = self._triangulate()
        if self.dims == 1:
            self._order = np.argsort(self._coords[:, 0], kind="stable")

    def _triangulate(self) -> Any:
        from scipy.spatial import Delaunay, QhullError  # imported when a phantom layout is first built

        try:
            return Delaunay(self._coords)
        except QhullError:  # nearly collinear: treat as a line
            self.dims = 1
            self._axes = self._axes[:1]
            self._coords = self._coords[:, :1]
            return None

    def weights(self, point: ArrayLike) -> NDArray[np.float64]:
        """Power weights of a source at ``point`` (they sum to 1; at most 3 are non-zero).

        Parameters
        ----------
        point : array_like, shape (3,) or (2,)

        Returns
        -------
        w : ndarray, shape (n_actuators,)
        """
        q = (_points(point, "point")[0] - self._origin) @ self._axes.T
        out = np.zeros(self.n)
        if self.dims == 0:
            out[:] = 1.0 / self.n
        elif self.dims == 1 or self._tri is None:
            self._along_line(float(q[0]), out)
        else:
            self._in_plane(q, out)
        return out

    def _along_line(self, u: float, out: NDArray[np.float64]) -> None:
        order = self._order
        coords = self._coords[order, 0]
        if u <= coords[0]:
            out[order[0]] = 1.0
            return
        if u >= coords[-1]:
            out[order[-1]] = 1.0
            return
        i = int(np.searchsorted(coords, u, side="right")) - 1
        span = coords[i + 1] - coords[i]
        t = 0.0 if span <= 0 else (u - coords[i]) / span
        out[order[i]] += 1.0 - t
        out[order[i + 1]] += t

    def _in_plane(self, q: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        tri = self._tri
        simplex = int(tri.find_simplex(q[np.newaxis])[0])
        if simplex >= 0:
            transform = tri.transform[simplex]
            b = transform[:2] @ (q - transform[2])
            bary = np.clip(np.array([b[0], b[1], 1.0 - b[0] - b[1]]), 0.0, None)
            out[tri.simplices[simplex]] += bary / bary.sum()
            return
        # outside the layout: between the two ends of the nearest edge of its outline
        edges = tri.convex_hull  # (m, 2) vertex indices
        a, b = self._coords[edges[:, 0]], self._coords[edges[:, 1]]
        ab = b - a
        length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / length2, 0.0, 1.0)
        gap = np.linalg.norm(a + t[:, np.newaxis] * ab - q, axis=1)
        best = int(np.argmin(gap))
        out[edges[best, 0]] += 1.0 - t[best]
        out[edges[best, 1]] += t[best]


class SpatialLayout:
    """Actuator positions and the roll-off weights of sources on them.

    Parameters
    ----------
    positions : array_like, shape (n_actuators, 3) or (n_actuators, 2)
        Metres.
    """

    def __init__(self, positions: ArrayLike) -> None:
        self.positions = _points(positions, "actuators")
        self._panner: PhantomPanner | None = None

    @property
    def n(self) -> int:
        return int(self.positions.shape[0])

    @property
    def panner(self) -> PhantomPanner:
        """The phantom panner (built on first use)."""
        if self._panner is None:
            self._panner = PhantomPanner(self.positions)
        return self._panner

    def weights(self, law: str, point: ArrayLike, radius: float) -> NDArray[np.float64]:
        """Power weights of one source on every actuator.

        Parameters
        ----------
        law : str
            One of :data:`ROLLOFFS`.
        point : array_like, shape (3,) or (2,)
        radius : float
            Metres (> 0; not used by ``phantom``).

        Returns
        -------
        w : ndarray, shape (n_actuators,)
        """
        if check_rolloff(law) == "phantom":
            return self.panner.weights(point)
        return rolloff_weights(law, distances(self.positions, point), radius)


class TextureSpectra:
    """The linear 30-band powers of a texture (intensity level, balance), and their analysis.

    A texture of balance ``b`` has the dB band spectrum ``M + t1(b) V1`` (plus a constant);
    the constant that puts its 80-200 Hz band level at 0 dB comes from the DSP core's
    spectral shaper (the band powers of the noise it synthesises for that spectrum), tabulated
    every :data:`SPECTRA_STEP` over the balance range and interpolated.

    Parameters
    ----------
    basis : Basis
    balance_min, balance_max : float
        The range of balances that will be asked for (values outside are clamped for the
        offset only).
    """

    def __init__(self, basis: Basis, *, balance_min: float = -3.5, balance_max: float = 3.5) -> None:
        if not (math.isfinite(balance_min) and math.isfinite(balance_max) and balance_min < balance_max):
            raise ParameterError(f"need a finite balance range, got [{balance_min}, {balance_max}]")
        self.basis = basis
        count = int(math.ceil((balance_max - balance_min) / SPECTRA_STEP)) + 1
        self.grid = np.linspace(balance_min, balance_max, count)
        shaper = SpectralShaper(fs=_SHAPER_FS, n_samples=_SHAPER_SAMPLES, centres=basis.centres_hz)
        shapes = basis.spectrum_for_balance(self.grid)  # (count, bands)
        offsets = np.empty(count)
        for i, shape in enumerate(shapes):
            measured = shaper.weights_band_db(shaper.solve_weights(shape, level_db=0.0))
            offsets[i] = _power_db(measured) - _power_db(shape)
        self.offsets_db = offsets

    def band_powers(self, level_db: ArrayLike, balance: ArrayLike) -> NDArray[np.float64]:
        """Linear band powers of textures at their intensity levels.

        Parameters
        ----------
        level_db : array_like, shape (n,)
            80-200 Hz band levels in dB (``-inf`` = silent: all zeros).
        balance : array_like, shape (n,)
            Knob units.

        Returns
        -------
        powers : ndarray, shape (n, n_bands)
        """
        level = np.atleast_1d(np.asarray(level_db, dtype=np.float64))
        bal = np.atleast_1d(np.asarray(balance, dtype=np.float64))
        shape = self.basis.spectrum_for_balance(bal) + np.interp(bal, self.grid, self.offsets_db)[:, np.newaxis]
        with np.errstate(over="ignore"):
            powers = 10.0 ** ((shape + np.where(np.isfinite(level), level, 0.0)[:, np.newaxis]) / 10.0)
        return np.asarray(np.where(np.isfinite(level)[:, np.newaxis], powers, 0.0), dtype=np.float64)

    def balance_of(self, band_powers: ArrayLike) -> NDArray[np.float64]:
        """Balance (knob units) of linear band spectra: V1 score of their normalised dB, as the analysis does.

        Parameters
        ----------
        band_powers : array_like, shape (..., n_bands)
            Positive powers.

        Returns
        -------
        balance : ndarray, shape (...,)
        """
        t1 = self.basis.scores(to_db(band_powers))[..., 0]
        return np.asarray(self.basis.balance_from_t1(t1), dtype=np.float64)


def _power_db(band_db: NDArray[np.float64]) -> float:
    """Total power (dB) of a dB band spectrum, computed without overflow."""
    top = float(band_db.max())
    return top + 10.0 * math.log10(float(np.sum(10.0 ** ((band_db - top) / 10.0))))


@dataclass(frozen=True)
class Mix:
    """What each actuator plays after mixing.

    Attributes
    ----------
    level_db : ndarray, shape (n_actuators,)
        80-200 Hz band level of the sum (``-inf`` where no source reaches).
    balance : ndarray, shape (n_actuators,)
        Balance of the summed spectrum (knob units; NaN where no source reaches).
    """

    level_db: NDArray[np.float64]
    balance: NDArray[np.float64]


def mix_sources(weights: ArrayLike, level_db: ArrayLike, balance: ArrayLike, spectra: TextureSpectra) -> Mix:
    """Mix sources on actuators in the perceptual model (see the module docstring).

    Parameters
    ----------
    weights : array_like, shape (n_sources, n_actuators)
        Power weights in [0, 1] (:meth:`SpatialLayout.weights` of each source).
    level_db : array_like, shape (n_sources,)
        Each source's 80-200 Hz band level (``-inf`` = silent).
    balance : array_like, shape (n_sources,)
        Each source's balance (knob units).
    spectra : TextureSpectra

    Returns
    -------
    mix : Mix
    """
    w = np.asarray(weights, dtype=np.float64)
    level = np.asarray(level_db, dtype=np.float64).reshape(-1)
    if w.ndim != 2 or w.shape[0] != level.size or np.asarray(balance).size != level.size:
        raise ParameterError(f"weights {w.shape} do not match {level.size} sources")
    if not (np.all(np.isfinite(w)) and np.all(w >= 0)):
        raise ParameterError("weights must be finite and >= 0")
    with np.errstate(under="ignore"):
        intensity_power = np.where(np.isfinite(level), 10.0 ** (np.where(np.isfinite(level), level, 0.0) / 10.0), 0.0)
    total = intensity_power @ w  # (n_actuators,)
    bands = w.T @ spectra.band_powers(level, balance)  # (n_actuators, n_bands)
    reached = (total > 0) & np.all(bands > 0, axis=1)
    out_level = np.full(w.shape[1], -np.inf)
    out_balance = np.full(w.shape[1], np.nan)
    if np.any(reached):
        out_level[reached] = 10.0 * np.log10(total[reached])
        out_balance[reached] = spectra.balance_of(bands[reached])
    return Mix(level_db=out_level, balance=out_balance)
