"""Actuator frequency response and its (boost-limited) inverse equaliser.

An actuator (voice coil, LRA, shaker) does not turn voltage into vibration with a
flat response. If its response is known as points ``(Hz, dB)``, the noise bank is
pre-equalised by the inverse response so the *felt* spectrum follows ``M + t V1``.
The inverse never boosts more than ``max_boost_db`` (a resonance-free actuator
at 10 Hz would otherwise ask for absurd drive); cuts are not limited. A measured
(``absolute``) profile is recorded level per unit of drive through a sensor chain, so
its 0 dB means nothing physical: its boost is limited relative to the response's own
level in the intensity band (:meth:`ActuatorResponse.reference_db`), which the bank's
band-level normalisation compensates anyway.

Interpolation is linear in dB over log-frequency; outside the given points the
response is held at the first/last value. With no points the response is flat
(0 dB) and the equaliser is the identity.

This module does no I/O: profiles' YAML files are read elsewhere and arrive here
as a list of points.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.dsp.intensity import intensity_response
from vibsynth.errors import ConfigError

__all__ = ["ActuatorResponse", "DEFAULT_MAX_BOOST_DB"]

DEFAULT_MAX_BOOST_DB = 12.0


@dataclass(frozen=True)
class ActuatorResponse:
    """Measured actuator response (Hz -> dB) and the inverse-EQ boost limit.

    Parameters
    ----------
    points : tuple of (float, float)
        ``(frequency_hz, gain_db)`` pairs, sorted by frequency, frequencies > 0 and
        distinct. Empty = flat.
    max_boost_db : float
        Largest gain (dB) the inverse equaliser may apply, >= 0 (above :meth:`reference_db`).
    absolute : bool
        A measured profile (see the module notes): the boost limit is relative to its band level.
    """

    points: tuple[tuple[float, float], ...] = ()
    max_boost_db: float = DEFAULT_MAX_BOOST_DB
    absolute: bool = False

    @classmethod
    def from_points(
        cls,
        points: Iterable[Sequence[float]] | None,
        *,
        max_boost_db: float = DEFAULT_MAX_BOOST_DB,
        absolute: bool = False,
    ) -> ActuatorResponse:
        """Validate points from a config file or profile.

        Parameters
        ----------
        points : iterable of [Hz, dB] or None
        max_boost_db : float

        Raises
        ------
        ConfigError
            Malformed points, non-positive or repeated frequencies, NaN values or a negative boost limit.
        """
        try:
            boost = float(max_boost_db)
        except (TypeError, ValueError):
            raise ConfigError(f"actuator.max_boost_db must be a number, got {max_boost_db!r}") from None
        if not math.isfinite(boost) or boost < 0:
            raise ConfigError(f"actuator.max_boost_db must be >= 0, got {max_boost_db!r}")
        parsed: list[tuple[float, float]] = []
        for i, point in enumerate(points or ()):
            try:
                hz, db = (float(v) for v in point)
            except (TypeError, ValueError):
                raise ConfigError(f"actuator.response[{i}] must be a pair [Hz, dB], got {point!r}") from None
            if not (math.isfinite(hz) and math.isfinite(db)) or hz <= 0:
                raise ConfigError(f"actuator.response[{i}] needs a frequency > 0 Hz and a finite dB, got {point!r}")
            parsed.append((hz, db))
        parsed.sort()
        freqs = [p[0] for p in parsed]
        if len(set(freqs)) != len(freqs):
            raise ConfigError("actuator.response has the same frequency twice")
        return cls(points=tuple(parsed), max_boost_db=boost, absolute=bool(absolute))

    @property
    def is_flat(self) -> bool:
        """True when the response is 0 dB everywhere (no equalisation needed)."""
        return all(db == 0.0 for _, db in self.points)

    def response_db(self, freqs: ArrayLike) -> NDArray[np.float64]:
        """Actuator gain in dB at frequencies (log-frequency interpolation, held at the ends).

        Parameters
        ----------
        freqs : array_like, shape (n,)
            Hz; values <= 0 take the lowest point's gain.

        Returns
        -------
        gain_db : ndarray, shape (n,)
        """
        f = np.asarray(freqs, dtype=np.float64)
        if not self.points:
            return np.zeros_like(f)
        hz = np.log(np.array([p[0] for p in self.points]))
        db = np.array([p[1] for p in self.points])
        with np.errstate(divide="ignore"):
            log_f = np.log(np.where(f > 0, f, self.points[0][0]))
        return np.asarray(np.interp(log_f, hz, db), dtype=np.float64)

    def reference_db(self) -> float:
        """The response's level in the intensity band (power mean, dB); 0 for a relative profile."""
        if not self.absolute or not self.points:
            return 0.0
        f = np.geomspace(10.0, 1000.0, 400)
        weight = intensity_response(f)
        power = 10.0 ** (self.response_db(f) / 10.0)
        return float(10.0 * np.log10(float(power @ weight) / float(weight.sum())))

    def inverse_gain(self, freqs: ArrayLike) -> NDArray[np.float64]:
        """Linear amplitude gain of the inverse equaliser, ``10^(min(-response, max_boost - reference)/20)``.

        Parameters
        ----------
        freqs : array_like, shape (n,)

        Returns
        -------
        gain : ndarray, shape (n,)
        """
        eq_db = np.minimum(-self.response_db(freqs), self.max_boost_db - self.reference_db())
        return 10.0 ** (eq_db / 20.0)

    def key(self) -> list[object]:
        """JSON-able identity for cache keys."""
        if self.absolute:
            return [[list(p) for p in self.points], self.max_boost_db, True]
        return [[list(p) for p in self.points], self.max_boost_db]
