"""Decoding a ``.vbt`` trajectory through the engine into samples."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.codec import Trajectory, knob_schedule
from vibsynth.errors import ParameterError


@dataclass(frozen=True)
class Rendered:
    """A trajectory rendered through the engine.

    Attributes
    ----------
    signal : ndarray, shape (n_samples,)
        Mono output (engine channel 0), float64.
    fs : float
    offset_db : float
        The output is this much quieter than the encoded levels (0 unless the
        trajectory would have hit the engine's limiter; see :func:`render`).
    ceiling_db, range_db : float
        Intensity mapping used.
    balance_clamped : int
        Windows whose balance lies outside the engine's bank (rendered at its edge).
    n_events : int
        SetKnob commands scheduled.
    """

    signal: NDArray[np.float64]
    fs: float
    offset_db: float
    ceiling_db: float
    range_db: float
    balance_clamped: int
    n_events: int


#: Headroom kept below the engine's limiter (dB) when choosing the offset.
LIMITER_MARGIN_DB = 0.5
#: Extra knob range below the trajectory's span (room for the offset; keeps every
#: non-silent window well above the engine's fade-in region, knob < 0.01).
RANGE_MARGIN_DB = 40.0
_MAX_CEILING_DB, _MAX_RANGE_DB = 0.0, 120.0


def render(
    trajectory: Trajectory,
    *,
    basis: Basis,
    rate: float | None = None,
    config_path: str | os.PathLike[str] | None = None,
    overrides: dict[str, Any] | None = None,
) -> Rendered:
    """Play a trajectory through the real-time engine (``vibsynth.app.service.build_engine``).

    Each window's (intensity, balance) becomes ``SetKnob`` commands at exact
    frames with linear glides (:func:`vibsynth.dsp.codec.knob_schedule`), rendered
    by :meth:`Engine.render`.

    Intensity: the file stores absolute levels (dB re unit RMS of the source). The
    engine's ceiling is set to the trajectory's loudest level (at most 0 dB, the
    config's limit) and its range spans the trajectory plus ``RANGE_MARGIN_DB``,
    so the output keeps the source's absolute level -- unless a window would be
    above 0 dB or would make the engine's safety limiter act (gain above
    ``limiter_ceiling / peak`` of the bank loop at its balance). Then every level
    is lowered by the smallest ``offset_db`` that avoids both (with
    ``LIMITER_MARGIN_DB`` headroom): the output is that much quieter, and the
    offset is reported so that metrics (and ``decode --absolute``) can add it back.

    Parameters
    ----------
    trajectory : Trajectory
    basis : Basis
        Must be the basis the file was encoded with.
    rate : float, optional
        Output rate (default: the source rate, rounded to an integer).
    config_path : path-like, optional
        Config file for the engine (bank grid, limiter, cache); default: packaged defaults.
    overrides : dict, optional
        Extra config overrides (dotted keys), e.g. ``{"bank.cache_dir": ""}``.

    Returns
    -------
    rendered : Rendered
    """
    from vibsynth.app.service import build_engine
    from vibsynth.engine.commands import SetKnob
    from vibsynth.settings.config import load_config

    if trajectory.basis_id != basis.id:
        raise ParameterError(f"the file was encoded with basis {trajectory.basis_id}, this basis is {basis.id}")
    fs = int(round(rate if rate is not None else trajectory.fs))
    loud = np.isfinite(trajectory.level_db)
    top, bottom = float(trajectory.level_db[loud].max()), float(trajectory.level_db[loud].min())
    ceiling = min(_MAX_CEILING_DB, top)
    range_db = min(_MAX_RANGE_DB, top - bottom + RANGE_MARGIN_DB)
    ov: dict[str, Any] = {
        "audio.rate": fs,
        "audio.channels": 1,
        "knobs.ceiling_db": ceiling,
        "knobs.range_db": range_db,
        "knobs.initial_intensity": 0.0,
    }
    ov.update(overrides or {})
    config = load_config(config_path, overrides=ov, user_file=False)
    engine = build_engine(config, basis=basis)
    bank = engine.bank
    balances = np.asarray(basis.balance_from_t1(trajectory.t1), dtype=np.float64)
    clamped = int(np.count_nonzero(loud & ((balances < bank.balances[0]) | (balances > bank.balances[-1]))))
    # The engine caps the gain at limiter_ceiling / peak(balance): keep every window below that.
    peaks = np.interp(np.clip(balances, bank.balances[0], bank.balances[-1]), bank.balances, bank.peaks)
    allowed = 20.0 * np.log10(engine.limiter_ceiling / peaks) - LIMITER_MARGIN_DB
    offset = max(0.0, top - engine.ceiling_db, float(np.max(trajectory.level_db[loud] - allowed[loud])))
    events = knob_schedule(
        trajectory, basis=basis, out_fs=fs, ceiling_db=engine.ceiling_db, range_db=engine.range_db, offset_db=offset
    )
    for ev in events:
        at = ev.frame if ev.frame > 0 else None
        engine.submit(SetKnob("intensity", ev.intensity, at_frame=at, glide_s=ev.glide_s))
        engine.submit(SetKnob("balance", ev.balance, at_frame=at, glide_s=ev.glide_s))
    n_out = int(round(trajectory.n_samples * fs / trajectory.fs))
    signal = engine.render(n_out)[:, 0].astype(np.float64)
    return Rendered(signal, float(fs), offset, float(engine.ceiling_db), float(engine.range_db), clamped, len(events))
