"""Noise with imposed band powers: exact closed-form synthesis and the paper's iteration.

Exact method (:class:`SpectralShaper`)
--------------------------------------
The signal is one period of a random-phase spectrum ``X_b = |X_b| e^{i phi_b}``,
so it loops seamlessly and its measured band powers are a linear function of the
per-bin power ``p_b``: ``P_k = sum_b |H_k(f_b)|^2 p_b``. The power envelope is a
non-negative combination of 30 smooth bumps,
``p(f) = df * sum_j g_j B_j(f)``, where ``B_j`` are raised-cosine (Hann) bumps on
log-frequency centred on the band centres, with one extra empty knot below the
first and above the last band (a partition of unity between 10 and 1000 Hz that
fades to nothing at 8.5 and 1172 Hz: no energy where an actuator would only
hiss). The 30x30 system ``P = G g`` is solved by non-negative least squares;
then one scale factor sets the 80-200 Hz intensity level. Because the magnitudes
are deterministic (only the phases are random), the measured band powers equal
the target to rounding, at any rate >= 2.4 kHz, in one pass.

Iterative reference (:func:`synthesize_iterative`)
--------------------------------------------------
The paper's procedure after McDermott & Simoncelli (2011): Gaussian noise is split
into the 30 sub-bands, each sub-band is scaled to its target power, the sub-bands
are recombined, and this repeats until the measured powers match.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.filterbank import (
    BAND_CENTRES_HZ,
    BAND_ORDER,
    BAND_RATIO,
    MIN_RATE_HZ,
    band_powers_from_bin_powers,
    bandpass_response,
    bin_powers,
)
from vibsynth.dsp.intensity import intensity_level_from_bin_powers, intensity_response
from vibsynth.errors import ParameterError

if TYPE_CHECKING:
    from vibsynth.dsp.basis import Basis

__all__ = [
    "SpectralShaper",
    "SynthesisResult",
    "synthesize",
    "synthesize_iterative",
]


def _check_target(band_db: ArrayLike, n_bands: int) -> NDArray[np.float64]:
    arr = np.asarray(band_db, dtype=np.float64)
    if arr.shape[-1] != n_bands:
        raise ParameterError(f"target spectrum must have {n_bands} bands, got {arr.shape[-1]}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError("target spectrum contains NaN or infinite values")
    return arr


def _check_level(level_db: float | None) -> None:
    if level_db is not None and not math.isfinite(level_db):
        raise ParameterError(f"target intensity level must be finite, got {level_db}")


class SpectralShaper:
    """Closed-form spectral shaping on one FFT grid (one rate, one length).

    Build once per (rate, length) and reuse for many targets (the engine's bank).

    Parameters
    ----------
    fs : float
        Sample rate in Hz (>= :data:`MIN_RATE_HZ`).
    n_samples : int
        Length of the (periodic) signal.
    centres : array_like, shape (n_bands,)
        Band centres; the analysis filter bank uses the same.
    order : int
        Analysis filter quality factor.

    Attributes
    ----------
    freqs : ndarray, shape (n_bins,)
        ``n_bins = n_samples // 2 + 1``.
    """

    def __init__(
        self,
        *,
        fs: float,
        n_samples: int,
        centres: ArrayLike = BAND_CENTRES_HZ,
        order: int = BAND_ORDER,
    ) -> None:
        if not math.isfinite(fs) or fs < MIN_RATE_HZ:
            raise ParameterError(f"sample rate {fs:g} Hz is too low (need >= {MIN_RATE_HZ:g} Hz)")
        if int(n_samples) < 16:
            raise ParameterError(f"need at least 16 samples, got {n_samples}")
        self.fs = float(fs)
        self.n_samples = int(n_samples)
        self.centres = np.asarray(centres, dtype=np.float64)
        self.order = int(order)
        self.freqs = np.fft.rfftfreq(self.n_samples, 1.0 / self.fs).astype(np.float64)
        self._df = self.fs / self.n_samples
        # Log-frequency knots: the band centres plus one empty knot at each end.
        log_c = np.log(self.centres)
        step = float(np.mean(np.diff(log_c))) if self.centres.size > 1 else math.log(BAND_RATIO)
        self._log_knots = np.concatenate(([log_c[0] - step], log_c, [log_c[-1] + step]))
        self._step = step
        # Per-bin Parseval factor: |X_b|^2 = p_b / factor_b.
        factor = np.full(self.freqs.size, 2.0 / self.n_samples**2)
        factor[0] *= 0.5
        if self.n_samples % 2 == 0:
            factor[-1] *= 0.5
        self._parseval = factor
        self._gain_matrix = self._band_gain_matrix()
        self._reachable: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {}
        self._intensity_row = self._bump_powers(intensity_response(self.freqs)[np.newaxis])[0]

    # ------------------------------------------------------------------ envelope
    def _bump_index(self) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.bool_]]:
        """For each bin: left knot index, cos^2/sin^2 weight position, and whether it lies inside."""
        with np.errstate(divide="ignore"):
            log_f = np.log(np.where(self.freqs > 0, self.freqs, np.nan))
        u = (log_f - self._log_knots[0]) / self._step
        inside = np.isfinite(u) & (u >= 0) & (u < self._log_knots.size - 1)
        idx = np.where(inside, np.floor(np.nan_to_num(u)), 0).astype(np.intp)
        frac = np.where(inside, np.nan_to_num(u) - idx, 0.0)
        return idx, frac, inside

    def power_envelope(self, weights: ArrayLike) -> NDArray[np.float64]:
        """Per-bin power ``p_b`` for bump weights ``g`` (one per band).

        Parameters
        ----------
        weights : array_like, shape (..., n_bands)
            Non-negative bump weights.

        Returns
        -------
        power : ndarray, shape (..., n_bins)
        """
        g = np.asarray(weights, dtype=np.float64)
        padded = np.concatenate([np.zeros(g.shape[:-1] + (1,)), g, np.zeros(g.shape[:-1] + (1,))], axis=-1)
        idx, frac, inside = self._bump_index()
        left = np.cos(0.5 * np.pi * frac) ** 2
        right = 1.0 - left
        env = padded[..., idx] * left + padded[..., np.minimum(idx + 1, padded.shape[-1] - 1)] * right
        return np.where(inside, env, 0.0) * self._df

    def _bump_powers(self, responses: NDArray[np.float64]) -> NDArray[np.float64]:
        """``sum_b responses[r, b] * B_j(f_b) * df`` for each response row and bump j."""
        n_bands = self.centres.size
        out = np.zeros((responses.shape[0], n_bands))
        idx, frac, inside = self._bump_index()
        left = np.cos(0.5 * np.pi * frac) ** 2 * self._df
        right = np.sin(0.5 * np.pi * frac) ** 2 * self._df
        n_knots = n_bands + 2
        left_idx, right_idx = idx[inside], idx[inside] + 1
        for r, row in enumerate(responses):
            # Bump j (padded index j+1) takes `left` from bins whose left knot is j+1 and `right` from j.
            acc = np.bincount(left_idx, weights=row[inside] * left[inside], minlength=n_knots)
            acc += np.bincount(right_idx, weights=row[inside] * right[inside], minlength=n_knots)
            out[r] = acc[1:-1]
        return out

    def _band_gain_matrix(self) -> NDArray[np.float64]:
        """G[k, j]: power measured in band k from bump j with unit weight."""
        return self._bump_powers(bandpass_response(self.freqs, centres=self.centres, order=self.order))

    # ------------------------------------------------------------------ solve
    def solve_weights(self, band_db: ArrayLike, *, level_db: float | None = None) -> NDArray[np.float64]:
        """Bump weights ``g >= 0`` whose measured band powers follow ``band_db``.

        Non-negative least squares on the linear band powers. (Weighting rows by
        1/target, i.e. relative errors, was tried: it spreads the error of
        unmeasurable targets over more bands and was worse in dB.)

        Parameters
        ----------
        band_db : array_like, shape (n_bands,)
            Target band spectrum in dB; only its shape matters when ``level_db`` is given.
        level_db : float, optional
            Target 80-200 Hz intensity level in dB. ``None`` keeps the absolute band powers.

        Returns
        -------
        weights : ndarray, shape (n_bands,)
        """
        target_db = _check_target(band_db, self.centres.size)
        _check_level(level_db)
        # Solve on a level-neutral scale, then rescale: keeps NNLS well conditioned.
        offset = float(target_db.mean())
        target = 10.0 ** ((target_db - offset) / 10.0)
        from scipy.optimize import nnls  # imported when first needed: scipy.optimize takes 0.3 s to load

        weights, _ = nnls(self._gain_matrix, target, maxiter=50 * target.size)
        if level_db is None:
            return np.asarray(weights * 10.0 ** (offset / 10.0), dtype=np.float64)
        current = float(self._intensity_row @ weights)
        if current <= 0:
            raise ParameterError("target spectrum has no energy in the 80-200 Hz band")
        return np.asarray(weights * 10.0 ** (level_db / 10.0) / current, dtype=np.float64)

    def weights_band_db(self, weights: ArrayLike) -> NDArray[np.float64]:
        """Band powers (dB) the analysis measures for bump weights (exact, no FFT).

        Parameters
        ----------
        weights : array_like, shape (..., n_bands)

        Returns
        -------
        band_db : ndarray, shape (..., n_bands)
        """
        return np.asarray(
            10.0 * np.log10(np.maximum(np.asarray(weights) @ self._gain_matrix.T, 1e-300)), dtype=np.float64
        )

    def solve(self, band_db: ArrayLike, *, level_db: float | None = None) -> NDArray[np.float64]:
        """Per-bin power whose band powers follow ``band_db`` (see :meth:`solve_weights`).

        Returns
        -------
        power : ndarray, shape (n_bins,)
            Per-bin power ``p_b`` (sums to the mean square).
        """
        return self.power_envelope(self.solve_weights(band_db, level_db=level_db))

    def reachable_t1(self, basis: Basis) -> tuple[tuple[float, float], tuple[float, float]]:
        """The lowest and highest t1 a signal shaped along ``M + t V1`` can *measure*.

        Far out, ``M + t V1`` has slopes steeper than the filter bank can show (a
        band cannot measure lower than what its neighbours leak into it), so the
        measured t1 saturates. Found by bounded maximisation; cached per basis.

        Returns
        -------
        (low, high) : tuple of (requested_t, measured_t1)
            For each side, the requested t that measures furthest out, and that t1.
        """
        key = basis.id
        if key not in self._reachable:

            def measured(requested: float) -> float:
                w = self.solve_weights(basis.mean_db + requested * basis.v1, level_db=0.0)
                return float(basis.scores(self.weights_band_db(w))[0])

            from scipy.optimize import minimize_scalar

            sides = []
            for sign, span in ((-1.0, -basis.t1_from_balance(-1.0)), (1.0, basis.t1_from_balance(1.0))):
                res = minimize_scalar(
                    lambda t: -sign * measured(sign * t),
                    bounds=(0.0, 12.0 * float(span)),
                    method="bounded",
                    options={"xatol": 1e-3 * float(span)},
                )
                sides.append((sign * float(res.x), measured(sign * float(res.x))))
            self._reachable[key] = (sides[0], sides[1])
        return self._reachable[key]

    def solve_balance(
        self,
        basis: Basis,
        balance: float,
        *,
        level_db: float,
        tolerance_t1: float = 1e-4,
    ) -> NDArray[np.float64]:
        """Bump weights for ``M + t1 V1`` whose *measured* t1 equals the balance's t1.

        Where ``M + t1 V1`` is measurable, this is :meth:`solve_weights`. Further out,
        the target's steepest slopes exceed what the filter bank can measure
        (adjacent-band leakage, -12 dB), so the measured t1 falls short; then the
        requested t is pushed further (Brent's method) until the measured t1 and the
        intensity are exact. Beyond the reachable range (:meth:`reachable_t1`; on the
        default basis about -4 to +2.3 balance) the result saturates at its edge, so
        the output stays monotonic in the balance.

        Parameters
        ----------
        basis : Basis
        balance : float
            Knob units.
        level_db : float
            Intensity level in dB.
        tolerance_t1 : float

        Returns
        -------
        weights : ndarray, shape (n_bands,)
        """
        goal = float(basis.t1_from_balance(balance))

        def solve_for(requested: float) -> NDArray[np.float64]:
            return self.solve_weights(basis.mean_db + requested * basis.v1, level_db=level_db)

        def miss(requested: float) -> float:
            return float(basis.scores(self.weights_band_db(solve_for(requested)))[0]) - goal

        first = miss(goal)
        if abs(first) <= tolerance_t1:
            return solve_for(goal)
        (low_req, low_t1), (high_req, high_t1) = self.reachable_t1(basis)
        if goal >= high_t1:
            return solve_for(high_req)
        if goal <= low_t1:
            return solve_for(low_req)
        edge = high_req if first < 0 else low_req
        from scipy.optimize import brentq

        requested = brentq(miss, min(goal, edge), max(goal, edge), xtol=tolerance_t1 / 10)
        return solve_for(requested)

    def magnitudes(self, power: ArrayLike) -> NDArray[np.float64]:
        """Spectrum magnitudes ``|X_b|`` for per-bin powers.

        Parameters
        ----------
        power : array_like, shape (..., n_bins)

        Returns
        -------
        magnitude : ndarray, shape (..., n_bins)
        """
        return np.asarray(np.sqrt(np.asarray(power, dtype=np.float64) / self._parseval), dtype=np.float64)

    def random_phases(self, rng: np.random.Generator) -> NDArray[np.complex128]:
        """Unit phasors ``e^{i phi}`` (DC and Nyquist real).

        Returns
        -------
        phasors : ndarray, shape (n_bins,)
        """
        phasors = np.exp(2j * np.pi * rng.random(self.freqs.size))
        phasors[0] = 1.0
        if self.n_samples % 2 == 0:
            phasors[-1] = 1.0
        return np.asarray(phasors, dtype=np.complex128)

    def render(self, power: ArrayLike, phasors: NDArray[np.complex128]) -> NDArray[np.float64]:
        """One period of the shaped noise.

        Parameters
        ----------
        power : array_like, shape (..., n_bins)
        phasors : ndarray, shape (n_bins,)

        Returns
        -------
        signal : ndarray, shape (..., n_samples)
        """
        return np.fft.irfft(self.magnitudes(power) * phasors, n=self.n_samples, axis=-1)

    def band_db(self, power: ArrayLike) -> NDArray[np.float64]:
        """Band powers (dB) that the analysis filter bank measures for per-bin powers.

        Parameters
        ----------
        power : array_like, shape (..., n_bins)

        Returns
        -------
        band_db : ndarray, shape (..., n_bands)
        """
        p = band_powers_from_bin_powers(
            self.freqs, np.asarray(power, dtype=np.float64), centres=self.centres, order=self.order
        )
        return 10.0 * np.log10(np.maximum(p, 1e-300))

    def level_db(self, power: ArrayLike) -> float:
        """Intensity level (dB) of per-bin powers, shape (n_bins,)."""
        return intensity_level_from_bin_powers(self.freqs, np.asarray(power, dtype=np.float64))


@dataclass(frozen=True)
class SynthesisResult:
    """A synthesized signal and what the analysis measures of it.

    Attributes
    ----------
    signal : ndarray, shape (n_samples,)
    band_db : ndarray, shape (n_bands,)
        Measured band powers (dB).
    level_db : float
        Measured intensity level (dB).
    max_band_error_db : float
        Largest |measured - target| over bands after removing the level offset
        (or absolute, when no intensity was imposed).
    iterations : int
        1 for the exact method.
    """

    signal: NDArray[np.float64]
    band_db: NDArray[np.float64]
    level_db: float
    max_band_error_db: float
    iterations: int


def _band_error(measured_db: NDArray[np.float64], target_db: NDArray[np.float64], relative: bool) -> float:
    diff = measured_db - target_db
    if relative:
        diff = diff - diff.mean()
    return float(np.max(np.abs(diff)))


def synthesize(
    band_db: ArrayLike,
    *,
    fs: float,
    n_samples: int,
    level_db: float | None = None,
    rng: np.random.Generator | None = None,
) -> SynthesisResult:
    """Noise whose 30-band powers equal a target spectrum, exactly, in closed form.

    The result is one period of a periodic signal: it loops seamlessly.

    Parameters
    ----------
    band_db : array_like, shape (n_bands,)
        Target band spectrum in dB.
    fs : float
        Sample rate in Hz (>= 2.4 kHz).
    n_samples : int
        Length in samples.
    level_db : float, optional
        Target intensity (80-200 Hz band level, dB). ``None``: absolute band powers.
    rng : numpy.random.Generator, optional
        Source of the random phases.

    Returns
    -------
    result : SynthesisResult
    """
    target = _check_target(band_db, BAND_CENTRES_HZ.size)
    shaper = SpectralShaper(fs=fs, n_samples=n_samples)
    power = shaper.solve(target, level_db=level_db)
    signal = shaper.render(power, shaper.random_phases(rng or np.random.default_rng()))
    measured = shaper.band_db(power)
    return SynthesisResult(
        signal=signal,
        band_db=measured,
        level_db=shaper.level_db(power),
        max_band_error_db=_band_error(measured, target, relative=level_db is not None),
        iterations=1,
    )


def synthesize_iterative(
    band_db: ArrayLike,
    *,
    fs: float,
    n_samples: int,
    level_db: float | None = None,
    rng: np.random.Generator | None = None,
    tolerance_db: float = 0.1,
    max_iterations: int = 200,
) -> SynthesisResult:
    """The paper's iterative synthesis (reference implementation, for comparison).

    Gaussian noise -> 30 sub-bands (zero-phase band-pass filtering) -> each sub-band
    scaled by ``sqrt(target / measured)`` -> sub-bands recombined (normalised so that
    the sub-band filters sum to one) -> repeat until every band is within
    ``tolerance_db`` or ``max_iterations`` is reached. The level is set at the end.

    Parameters
    ----------
    band_db : array_like, shape (n_bands,)
    fs : float
    n_samples : int
    level_db : float, optional
    rng : numpy.random.Generator, optional
    tolerance_db : float
    max_iterations : int

    Returns
    -------
    result : SynthesisResult
        ``iterations`` is the number of passes made.
    """
    target_db = _check_target(band_db, BAND_CENTRES_HZ.size)
    _check_level(level_db)
    if not math.isfinite(fs) or fs < MIN_RATE_HZ:
        raise ParameterError(f"sample rate {fs:g} Hz is too low (need >= {MIN_RATE_HZ:g} Hz)")
    rng = rng or np.random.default_rng()
    freqs = np.fft.rfftfreq(n_samples, 1.0 / fs)
    subband = np.sqrt(bandpass_response(freqs, centres=BAND_CENTRES_HZ))  # (bands, bins)
    coverage = subband.sum(axis=0)
    # Outside the bank's span the recombination has no support: leave those bins empty.
    support = coverage > 1e-3 * coverage.max()
    target = 10.0 ** ((target_db - target_db.mean()) / 10.0)
    spectrum = np.fft.rfft(rng.standard_normal(n_samples))
    spectrum[~support] = 0.0
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - read after the loop
        signal = np.fft.irfft(spectrum, n=n_samples)
        freqs_b, power = bin_powers(signal, fs=fs)
        measured = band_powers_from_bin_powers(freqs_b, power)
        measured_db = 10.0 * np.log10(np.maximum(measured, 1e-300))
        if _band_error(measured_db, target_db, relative=True) <= tolerance_db:
            break
        scale = target.sum() / measured.sum()  # compare shapes, not levels
        gains = np.sqrt(target / (measured * scale))
        recombined = (gains[:, np.newaxis] * subband).sum(axis=0)
        spectrum = spectrum * np.where(support, recombined / np.where(support, coverage, 1.0), 0.0)
    signal = np.fft.irfft(spectrum, n=n_samples)
    freqs_b, power = bin_powers(signal, fs=fs)
    if level_db is not None:
        current = intensity_level_from_bin_powers(freqs_b, power)
        gain = 10.0 ** ((level_db - current) / 20.0)
        signal, power = signal * gain, power * gain**2
    measured_db = 10.0 * np.log10(np.maximum(band_powers_from_bin_powers(freqs_b, power), 1e-300))
    return SynthesisResult(
        signal=signal,
        band_db=measured_db,
        level_db=intensity_level_from_bin_powers(freqs_b, power),
        max_band_error_db=_band_error(measured_db, target_db, relative=True),
        iterations=iterations,
    )
