"""Iso-intensity curves (the paper's Fig. 1b) from intensity sessions on a set of sines.

Each participant matched every sine's intensity to a reference sine (default 250 Hz) by its
gain; a sine and the reference are generated at one drive level, so the gain *is* the drive
(voltage) that feels as intense as the reference: ``20 log10(gain)`` dB re the reference's
drive. A staircase session gives each sine's staircase estimate instead
(:mod:`~vibsynth.research.lab.staircase`). Repetitions are averaged in dB (geometric mean of
gains), participants too (the paper's geometric mean), with their SD. With an actuator's measured response ``R(f)``
(acceleration per unit drive, dB), the same curve in acceleration is
``V(f) + R(f) - R(f_ref)`` (dB re the reference's acceleration): the curve
:func:`vibsynth.dsp.measure_band.device_band` takes.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibsynth.errors import InputError
from vibsynth.research.lab.analysis import analyze_intensity
from vibsynth.research.lab.session import Session, json_ready

__all__ = ["IsoCurve", "is_sine_session", "iso_curve", "response_at"]


def is_sine_session(session: Session) -> bool:
    """The session matched sines to a reference sine (an iso-intensity session)."""
    return session.protocol == "intensity" and session.meta["set"].get("kind") == "sines"


def response_at(points: ArrayLike, freqs_hz: ArrayLike) -> NDArray[np.float64]:
    """A response given as ``[[Hz, dB], ...]`` at ``freqs_hz``, interpolated on log-frequency (ends held).

    Parameters
    ----------
    points : array_like, shape (m, 2)
    freqs_hz : array_like, shape (n,)

    Returns
    -------
    db : ndarray, shape (n,)
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2 or not np.all(np.isfinite(p)) or np.any(p[:, 0] <= 0):
        raise InputError("a response must be [[Hz, dB], ...] with at least 2 finite points, Hz > 0")
    order = np.argsort(p[:, 0])
    f = np.asarray(freqs_hz, dtype=np.float64)
    return np.asarray(np.interp(np.log(f), np.log(p[order, 0]), p[order, 1]), dtype=np.float64)


@dataclass(frozen=True)
class IsoCurve:
    """An iso-intensity curve over one or more participants.

    Attributes
    ----------
    freqs_hz : ndarray, shape (n,)
        The sines, increasing.
    ids : list of str
        Their stimulus ids.
    reference_hz : float
    participants : list of str
    voltage_db : ndarray, shape (n_participants, n)
        Each participant's drive for equal intensity, dB re the reference sine's (nan: not answered).
    mean_db, sd_db : ndarray, shape (n,)
        Mean over participants (dB, i.e. the geometric mean of gains) and its SD (nan for one).
    acceleration_db : ndarray or None, shape (n,)
        ``mean_db + R(f) - R(reference_hz)`` with a response ``R`` given.
    """

    freqs_hz: NDArray[np.float64]
    ids: list[str]
    reference_hz: float
    participants: list[str]
    voltage_db: NDArray[np.float64]
    mean_db: NDArray[np.float64]
    sd_db: NDArray[np.float64]
    acceleration_db: NDArray[np.float64] | None = None

    @property
    def labels(self) -> list[str]:
        """A column label per participant (``p01``; ``p01#2`` for a second session of one participant)."""
        seen: dict[str, int] = {}
        out = []
        for who in self.participants:
            seen[who] = seen.get(who, 0) + 1
            out.append(who if seen[who] == 1 else f"{who}#{seen[who]}")
        return out

    def rows(self) -> list[dict[str, Any]]:
        """One row per frequency: ``frequency_hz``, ``mean_db``, ``sd_db``, ``n``, each participant's dB
        (``db_<participant>``) and, with a response, ``acceleration_db``."""
        out = []
        for k, f in enumerate(self.freqs_hz):
            col = self.voltage_db[:, k]
            row: dict[str, Any] = {
                "frequency_hz": float(f),
                "mean_db": float(self.mean_db[k]),
                "sd_db": float(self.sd_db[k]),
                "n": int(np.isfinite(col).sum()),
            }
            if self.acceleration_db is not None:
                row["acceleration_db"] = float(self.acceleration_db[k])
            for who, v in zip(self.labels, col):
                row[f"db_{who}"] = float(v)
            out.append(row)
        return out

    def to_csv(self) -> str:
        """:meth:`rows` as CSV text (dB to 0.01; empty cells for nan)."""
        rows = self.rows()
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow(
                {k: ("" if isinstance(v, float) and not math.isfinite(v) else round(v, 2)) for k, v in row.items()}
            )
        return buffer.getvalue()

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON: nan is null)."""
        return json_ready(
            {
                "frequency_hz": self.freqs_hz,
                "ids": self.ids,
                "reference_hz": self.reference_hz,
                "participants": self.participants,
                "voltage_db": self.voltage_db,
                "mean_db": self.mean_db,
                "sd_db": self.sd_db,
                "acceleration_db": self.acceleration_db,
            }
        )


def iso_curve(sessions: Sequence[Session], *, response: ArrayLike | None = None) -> IsoCurve:
    """The iso-intensity curve of intensity sessions on one set of sines (complete or not).

    Parameters
    ----------
    sessions : sequence of Session
        One per participant (several sessions of one participant count as several).
    response : array_like, shape (m, 2), optional
        An actuator profile's measured response ``[[Hz, dB], ...]``: adds the curve in acceleration.

    Raises
    ------
    InputError
        Sessions that are not on sines, differ in set or reference, or have no answer.
    """
    for s in sessions:
        if not is_sine_session(s):
            raise InputError(f"{s.folder}: not an iso-intensity session (intensity on a set of sines)")
    refs = {float(s.meta["set"]["reference_hz"]) for s in sessions}
    if len(refs) != 1:
        raise InputError(
            f"the sessions used different reference sines ({', '.join(f'{r:g} Hz' for r in sorted(refs))})"
        )
    result = analyze_intensity(sessions)
    params = sessions[0].params()
    freqs = np.array([float(params[sid]["frequency_hz"]) for sid in result.ids])
    order = np.argsort(freqs)
    voltage = 20.0 * np.log10(result.gains[:, order])
    for k, session in enumerate(sessions):
        if session.method != "adjustment":  # the staircase's estimate, not the mean of the gains it played
            voltage[k] = [session.track(result.ids[j]).estimate_db for j in order]
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(voltage, axis=0)
            sd = np.nanstd(voltage, axis=0, ddof=1) if len(sessions) > 1 else np.full(freqs.size, np.nan)
    reference_hz = refs.pop()
    accel = None
    if response is not None:
        r = response_at(response, np.append(freqs[order], reference_hz))
        accel = mean + r[:-1] - r[-1]
    return IsoCurve(
        freqs_hz=freqs[order],
        ids=[result.ids[k] for k in order],
        reference_hz=reference_hz,
        participants=result.participants,
        voltage_db=voltage,
        mean_db=mean,
        sd_db=sd,
        acceleration_db=accel,
    )
