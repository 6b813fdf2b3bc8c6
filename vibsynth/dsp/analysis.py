"""Recording -> the two perceptual attributes (and what science users need besides).

:func:`analyze` measures a stationary recording's intensity (80-200 Hz band level),
its high/low balance (t1 on the basis' V1, and in knob units), all 8 scores, the
30-band dB spectrum, and the paper's non-stationarity metric. :func:`variant_spectra`
gives the target spectra of the paper's experiment-3 stimuli (S1, S1:8, S2:8, M).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.basis import Basis, to_db
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting
from vibsynth.dsp.filterbank import band_powers_from_bin_powers, bin_powers, validate_signal
from vibsynth.dsp.intensity import (
    DEFAULT_CEILING_DB,
    DEFAULT_RANGE_DB,
    SILENCE_DB,
    level_db_to_knob,
    non_stationarity_db,
)
from vibsynth.errors import ParameterError

__all__ = ["MIN_DURATION_S", "VARIANTS", "Analysis", "analyze", "variant_spectra"]

#: Shortest analysable recording: 5 periods of the lowest band (10 Hz) and
#: enough 100 ms windows (9) for the non-stationarity metric.
MIN_DURATION_S = 0.5

#: The paper's experiment-3 variants: which components each keeps.
VARIANTS: dict[str, slice | None] = {
    "S1": slice(0, 1),
    "S1:8": slice(0, None),
    "S2:8": slice(1, None),
    "M": None,
}


@dataclass(frozen=True)
class Analysis:
    """What :func:`analyze` measures of a recording.

    Attributes
    ----------
    level_db : float
        Intensity: the felt level under the weighting (by default the paper's 80-200 Hz
        Butterworth band level), dB re unit RMS.
    intensity_knob : float
        The knob value that renders this level under the given mapping (not clamped:
        outside [0, 1] means outside the knob's range).
    balance : float
        High/low balance in knob units (0 = M, +-1 = 98th/2nd percentile of the database).
    t1 : float
        Raw first PCA score.
    scores : ndarray, shape (n_components,)
        T1..T8.
    band_db : ndarray, shape (n_bands,)
        30-band spectrum in dB (absolute, unit of the recording squared).
    non_stationarity_db : float
        Std of the intensity level over 100 ms windows with 50 ms hop.
    duration_s : float
    fs : float
    outside_database : bool
        t1 lies outside the range of the basis' database (still represented, not clamped).
    """

    level_db: float
    intensity_knob: float
    balance: float
    t1: float
    scores: NDArray[np.float64]
    band_db: NDArray[np.float64]
    non_stationarity_db: float
    duration_s: float
    fs: float
    outside_database: bool

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data (arrays as lists)."""
        out = asdict(self)
        out["scores"] = self.scores.tolist()
        out["band_db"] = self.band_db.tolist()
        return out


def analyze(
    x: ArrayLike,
    *,
    fs: float,
    basis: Basis,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
    weighting: IntensityWeighting = PAPER_WEIGHTING,
) -> Analysis:
    """Analyse a stationary vibration recording.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        Mono recording; DC is ignored.
    fs : float
        Sample rate in Hz (>= 2.4 kHz).
    basis : Basis
        Spectral basis giving M and V1..V8.
    ceiling_db, range_db : float
        Intensity knob mapping used for ``intensity_knob``.
    weighting : IntensityWeighting
        What intensity means (:mod:`vibsynth.dsp.felt_intensity`): the paper's band, or a
        calibrated device's own weighting; the recording is taken as the felt signal.

    Returns
    -------
    analysis : Analysis

    Raises
    ------
    ParameterError
        Not mono, NaN/inf samples, rate too low, shorter than :data:`MIN_DURATION_S`,
        or silent (no power in the bands).
    """
    arr = validate_signal(x, fs=fs, min_seconds=MIN_DURATION_S)
    freqs, power = bin_powers(arr, fs=fs)
    bands = band_powers_from_bin_powers(freqs, power, centres=basis.centres_hz, order=basis.filter_order)
    level = weighting.level_from_bin_powers(freqs, power)
    if level <= SILENCE_DB or not np.all(bands > 0) or 10 * math.log10(bands.max()) <= SILENCE_DB:
        raise ParameterError("signal is silent: no power in the 10-1000 Hz bands")
    band_db = to_db(bands)
    scores = basis.scores(band_db)
    t1 = float(scores[0])
    return Analysis(
        level_db=level,
        intensity_knob=level_db_to_knob(level, ceiling_db=ceiling_db, range_db=range_db),
        balance=float(basis.balance_from_t1(t1)),
        t1=t1,
        scores=scores,
        band_db=band_db,
        non_stationarity_db=non_stationarity_db(arr, fs=fs),
        duration_s=arr.size / fs,
        fs=float(fs),
        outside_database=not basis.t1_in_database_range(t1),
    )


def variant_spectra(analysis: Analysis, basis: Basis) -> dict[str, NDArray[np.float64]]:
    """Target spectra of the paper's experiment-3 variants of a recording.

    Parameters
    ----------
    analysis : Analysis
    basis : Basis

    Returns
    -------
    spectra : dict of str to ndarray, shape (n_bands,)
        ``"S1"`` = M + t1 V1, ``"S1:8"`` = all components, ``"S2:8"`` = all but the
        first, ``"M"`` = the mean spectrum. Level-normalised dB; synthesize each at
        ``analysis.level_db``.
    """
    out = {}
    for name, components in VARIANTS.items():
        if components is None:
            out[name] = basis.mean_db.copy()
        else:
            out[name] = basis.reconstruct(analysis.scores, components=components)
    return out


def check_variant(name: str) -> str:
    """Validate a variant name (S1, S1:8, S2:8, M)."""
    if name not in VARIANTS:
        raise ParameterError(f"unknown variant {name!r}; choose one of {', '.join(VARIANTS)}")
    return name
