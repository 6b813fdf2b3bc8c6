r"""Per-channel trims: equalise a channel whose actuator differs from the one the bank was built for.

The noise bank is pre-equalised for one reference response ``R_0``; channel ``c``'s actuator
has ``R_c``. Its felt spectrum is the bank's felt spectrum times ``d(f) = R_c(f) - R_0(f)``
(dB), at every balance. The paper's model says a texture is perceived through two numbers
only: its **intensity** (the weighted band level, :mod:`vibsynth.dsp.felt_intensity`) and its
**balance** (the V1 score ``t1`` of its level-normalised 30-band spectrum). So two scalars per
channel equalise both:

* ``d`` shifts each band of the texture by ``D_k`` dB (computed on the texture's own spectrum,
  so a resonance inside a band counts as the texture feels it), which moves the score by
  ``dt1 = D . V1`` (V1 has zero band-mean: a level change does not move it). The channel's
  **balance offset** is the knob distance of ``-dt1``: ``balance_from_t1(-dt1)``.
* After that offset the channel plays another bank level ``j``, whose felt intensity ``d``
  changes by ``dL_j`` dB (under the weighting the bank was normalised with, or the channel's
  own calibrated weighting). The **gain curve** is ``-dL_j`` over the bank's levels: the engine
  reads it at the channel's effective bank position, so the intensity is right at every balance
  (a resonance inside the intensity band moves it by more at a dark balance than at a bright one,
  where the band's power is leakage from above; one gain would be up to ±1 dB off at ±1 for a
  6 dB resonance).

The offset is the mean of the exact offsets over the bank levels whose balance lies in
``balance_range`` (by default the basis' database range, -1..+1); their spread says how
constant it is (a thousandth of a balance unit for smooth responses).
What two scalars cannot equalise is the **residual**: the part of ``D`` orthogonal to V1 and
to a level change (``D - mean(D) - dt1 V1``), reported in dB per band. The model says it is
not perceived; it is where a vest's channels still differ physically.

The offset is exact at balance 0 and, away from it, within the basis' asymmetry between its
+1 and -1 percentiles (0.8 % of the offset for the shipped basis). No I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.basis import Basis, normalise_db
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting
from vibsynth.dsp.filterbank import band_powers_from_bin_powers
from vibsynth.errors import ParameterError

__all__ = ["ChannelTrim", "IDENTITY_TRIM", "channel_trim"]


@dataclass(frozen=True)
class ChannelTrim:
    """What a channel's actuator needs on top of the bank.

    Attributes
    ----------
    gain_curve_db : ndarray, shape (levels,)
        The gain (dB) at each bank level, after ``max_gain_db``: what the engine applies at
        the channel's effective bank position.
    gain : float
        Linear gain at balance 0 (``10^(gain_db/20)``).
    gain_db : float
        ``gain_curve_db`` at the bank position of balance 0 plus the offset.
    balance_offset : float
        Added to the channel's balance knob (knob units).
    t1_shift : float
        ``dt1``: how far the channel's response moves the texture's raw V1 score.
    wanted_gain_db : float
        The largest gain of the curve before ``max_gain_db`` (over ``balance_range``).
    limited : bool
        The curve reached ``max_gain_db`` somewhere in ``balance_range``.
    delta_bands_db : ndarray, shape (n_bands,)
        ``D``: the shift of each band of the texture (mean over the balances used).
    residual_db : ndarray, shape (n_bands,)
        ``D - mean(D) - dt1 V1``: what the trim cannot equalise.
    residual_rms_db, residual_max_db : float
        Its RMS and largest magnitude over the bands.
    gain_spread_db, balance_spread : float
        Peak-to-peak of the gain curve and of the exact offset over the balances used.
    """

    gain_curve_db: NDArray[np.float64] | None = None
    gain: float = 1.0
    gain_db: float = 0.0
    balance_offset: float = 0.0
    t1_shift: float = 0.0
    wanted_gain_db: float = 0.0
    limited: bool = False
    delta_bands_db: NDArray[np.float64] | None = None
    residual_db: NDArray[np.float64] | None = None
    residual_rms_db: float = 0.0
    residual_max_db: float = 0.0
    gain_spread_db: float = 0.0
    balance_spread: float = 0.0

    @property
    def is_identity(self) -> bool:
        """No gain and no offset."""
        flat = self.gain_curve_db is None or not np.any(self.gain_curve_db)
        return flat and self.balance_offset == 0.0

    def gains(self, levels: int) -> NDArray[np.float64]:
        """The linear gain curve for a bank of ``levels`` levels (ones without a curve), shape (levels,)."""
        if self.gain_curve_db is None:
            return np.ones(levels)
        if self.gain_curve_db.size != levels:
            raise ParameterError(f"the trim was derived for {self.gain_curve_db.size} bank levels, not {levels}")
        return np.asarray(10.0 ** (self.gain_curve_db / 20.0), dtype=np.float64)

    def describe(self) -> str:
        """``gain +3.2 dB (+2.9..+3.6), balance -0.120 (residual 0.40 dB RMS, 1.10 dB max)``."""
        text = f"gain {self.gain_db:+.1f} dB"
        if self.gain_spread_db >= 0.05:
            text += f" (spread {self.gain_spread_db:.1f} dB over balance -1..+1)"
        text += f", balance {round(self.balance_offset, 3) + 0.0:+.3f}"  # + 0.0: no "-0.000"
        if self.limited:
            text += f" (wanted {self.wanted_gain_db:+.1f} dB: limited)"
        return text + f" (residual {self.residual_rms_db:.2f} dB RMS, {self.residual_max_db:.2f} dB max)"


#: No trim.
IDENTITY_TRIM = ChannelTrim()


def channel_trim(
    basis: Basis,
    freqs: ArrayLike,
    felt_power: ArrayLike,
    balances: ArrayLike,
    delta_db: ArrayLike,
    *,
    weighting: IntensityWeighting = PAPER_WEIGHTING,
    channel_weighting: IntensityWeighting | None = None,
    balance_range: tuple[float, float] = (-1.0, 1.0),
    max_gain_db: float = math.inf,
) -> ChannelTrim:
    """The gain and balance offset that give a channel the bank's felt intensity and balance.

    Parameters
    ----------
    basis : Basis
        The basis the bank was built from (its bands, V1 and balance units).
    freqs : array_like, shape (n_bins,)
        Hz.
    felt_power : array_like, shape (levels, n_bins)
        Per-bin power of each bank level as the reference actuator ``R_0`` renders it (felt).
    balances : array_like, shape (levels,)
        The levels' balances, increasing.
    delta_db : array_like, shape (n_bins,)
        ``d = R_c - R_0`` at ``freqs`` (dB).
    weighting : IntensityWeighting
        The intensity weighting the bank was normalised with.
    channel_weighting : IntensityWeighting, optional
        The channel's own calibrated weighting (default ``weighting``): its felt level under it
        is brought to the knob's.
    balance_range : (float, float)
        The balances the trim is averaged over (levels outside are ignored; all when none is inside).
    max_gain_db : float
        The largest gain the trim may apply (``actuator.max_boost_db``).

    Returns
    -------
    trim : ChannelTrim
    """
    f = np.asarray(freqs, dtype=np.float64)
    p = np.asarray(felt_power, dtype=np.float64)
    b = np.asarray(balances, dtype=np.float64)
    d = np.asarray(delta_db, dtype=np.float64)
    if f.ndim != 1 or p.ndim != 2 or p.shape[1] != f.size or d.shape != f.shape or b.shape != (p.shape[0],):
        raise ParameterError("channel_trim: freqs (n,), felt_power (levels, n), balances (levels,), delta_db (n,)")
    if b.size < 2 or np.any(np.diff(b) <= 0) or not (np.all(np.isfinite(d)) and np.all(np.isfinite(p))):
        raise ParameterError("channel_trim: at least two increasing balances and finite spectra")
    if math.isnan(max_gain_db):
        raise ParameterError("channel_trim: max_gain_db must be a number")
    scale = 10.0 ** (d / 10.0)
    both = band_powers_from_bin_powers(
        f, np.concatenate([p, p * scale]), centres=basis.centres_hz, order=basis.filter_order
    )
    ref, own = both[: b.size], both[b.size :]
    if np.any(ref <= 0) or np.any(own <= 0):
        raise ParameterError("channel_trim: the texture has an empty band")
    shift = 10.0 * np.log10(own / ref)  # (levels, bands)
    dt1 = shift @ basis.v1
    felt_ref = weighting.levels_from_bin_powers(f, p)
    felt_own = (channel_weighting or weighting).levels_from_bin_powers(f, p * scale)
    if np.any(felt_ref <= 0) or np.any(felt_own <= 0):
        raise ParameterError(f"channel_trim: the texture has no power under {weighting.describe()}")
    level_shift = 10.0 * np.log10(felt_own / felt_ref)  # (levels,)
    inside = (b >= balance_range[0]) & (b <= balance_range[1])
    if not np.any(inside):
        inside = np.ones(b.size, dtype=bool)
    t1_shift = float(dt1[inside].mean())
    offset = float(basis.balance_from_t1(-t1_shift))
    exact_offsets = basis.balance_from_t1(-dt1[inside])
    curve = np.minimum(-level_shift, float(max_gain_db))
    used = -np.interp(b[inside] + offset, b, level_shift)
    wanted = float(used.max())
    gain_db = float(np.interp(offset, b, curve))
    bands = shift[inside].mean(axis=0)
    residual = normalise_db(bands) - (bands @ basis.v1) * basis.v1
    return ChannelTrim(
        gain_curve_db=curve,
        gain=float(10.0 ** (gain_db / 20.0)),
        gain_db=gain_db,
        balance_offset=offset,
        t1_shift=t1_shift,
        wanted_gain_db=wanted,
        limited=wanted > float(max_gain_db),
        delta_bands_db=bands,
        residual_db=residual,
        residual_rms_db=float(np.sqrt(np.mean(residual**2))),
        residual_max_db=float(np.abs(residual).max()),
        gain_spread_db=float(np.ptp(used)),
        balance_spread=float(np.ptp(exact_offsets)),
    )
