"""Decoding a ``.vbt`` trajectory through the engine, with the one offline renderer (:mod:`vibsynth.app.render`).

Levels, limiter and range margin (decided up front, no pass over the audio)
--------------------------------------------------------------------------
The file stores absolute levels. The engine's ceiling is set to the trajectory's loudest
level (at most 0 dB) and its range spans the trajectory plus :data:`RANGE_MARGIN_DB`. If a
window would be above 0 dB or would make the engine's safety limiter act, every level is
lowered by one ``offset_db``. That offset is computed from the trajectory alone: the
limiter caps the gain at ``limiter_ceiling / peak(balance)`` and the bank's per-level peaks
are known before any sample is rendered, so the windows' levels and balances say exactly
how much headroom is missing (plus :data:`LIMITER_MARGIN_DB`). No peak normalisation of
the rendered signal is needed, hence no second pass and no stored audio: the knob moves
(:func:`vibsynth.dsp.codec.knob_schedule`) are a timeline of cues that
:func:`vibsynth.app.render.render` feeds to the engine block by block (so a long file
never fills the engine's schedule), and the samples stream into the sink.
``decode --absolute`` undoes the offset with a :class:`~vibsynth.app.render.GainSink`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.app import render as offline
from vibsynth.app.render import DEFAULT_BLOCK, MAX_COLLECT_BYTES, ArrayCollector, Cue, RenderResult, Sink
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.codec import KnobEvent, Trajectory, knob_schedule
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError

__all__ = ["Rendered", "VbtRender", "prepare", "render_to", "render", "LIMITER_MARGIN_DB", "RANGE_MARGIN_DB"]


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
        trajectory would have hit the engine's limiter; see :func:`prepare`).
    ceiling_db, range_db : float
        Intensity mapping used.
    balance_clamped : int
        Windows whose balance lies outside the engine's bank (rendered at its edge).
    n_events : int
        Knob moves (each sets intensity and balance).
    """

    signal: NDArray[np.float64]
    fs: float
    offset_db: float
    ceiling_db: float
    range_db: float
    balance_clamped: int
    n_events: int


@dataclass(frozen=True)
class VbtRender:
    """A trajectory ready to render: the engine, its timeline, the length and the level decisions.

    Attributes
    ----------
    engine : Engine
        Mono, built for this trajectory's levels.
    timeline : iterator of Cue
        Two :class:`~vibsynth.engine.commands.SetKnob` cues (intensity, balance) per knob move,
        made while rendering (so it can be rendered once).
    frames : int
        Output length at ``fs``.
    fs, offset_db, ceiling_db, range_db, balance_clamped, n_events
        As in :class:`Rendered`.
    """

    engine: Engine
    timeline: Iterator[Cue]
    frames: int
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


def prepare(
    trajectory: Trajectory,
    *,
    basis: Basis,
    rate: float | None = None,
    config_path: str | os.PathLike[str] | None = None,
    overrides: dict[str, Any] | None = None,
) -> VbtRender:
    """Build the engine (``vibsynth.app.service.build_engine``) and the knob timeline that play a trajectory.

    Each window's (intensity, balance) becomes ``SetKnob`` cues at exact frames with
    linear glides (:func:`vibsynth.dsp.codec.knob_schedule`).

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
    job : VbtRender
    """
    from vibsynth.app.service import build_engine
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
    engine = build_engine(config.settings, basis=basis)
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
    n_out = int(round(trajectory.n_samples * fs / trajectory.fs))
    return VbtRender(
        engine=engine,
        timeline=_timeline(events),
        frames=n_out,
        fs=float(fs),
        offset_db=offset,
        ceiling_db=float(engine.ceiling_db),
        range_db=float(engine.range_db),
        balance_clamped=clamped,
        n_events=len(events),
    )


def _timeline(events: list[KnobEvent]) -> Iterator[Cue]:
    for ev in events:
        yield Cue(ev.frame, SetKnob("intensity", ev.intensity, glide_s=ev.glide_s))
        yield Cue(ev.frame, SetKnob("balance", ev.balance, glide_s=ev.glide_s))


def render_to(
    job: VbtRender,
    sink: Sink,
    *,
    block: int = DEFAULT_BLOCK,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """Render a prepared trajectory into ``sink`` (shape (frames, 1) blocks of float32)."""
    return offline.render(job.engine, job.frames, sink, timeline=job.timeline, block=block, progress=progress)


def render(
    trajectory: Trajectory,
    *,
    basis: Basis,
    rate: float | None = None,
    config_path: str | os.PathLike[str] | None = None,
    overrides: dict[str, Any] | None = None,
) -> Rendered:
    """Play a trajectory through the real-time engine into an array (see :func:`prepare`).

    For the quality check of ``vibsynth encode`` and for tests; ``vibsynth decode``
    streams to the WAV file with :func:`prepare` and :func:`render_to` instead. The
    array may be as large as the float64 source the caller already holds (or
    :data:`~vibsynth.app.render.MAX_COLLECT_BYTES`, whichever is larger).

    Returns
    -------
    rendered : Rendered
    """
    job = prepare(trajectory, basis=basis, rate=rate, config_path=config_path, overrides=overrides)
    limit = max(MAX_COLLECT_BYTES, 8 * int(trajectory.n_samples))
    collected = render_to(job, ArrayCollector(job.frames, 1, max_bytes=limit)).output
    return Rendered(
        collected[:, 0].astype(np.float64),
        job.fs,
        job.offset_db,
        job.ceiling_db,
        job.range_db,
        job.balance_clamped,
        job.n_events,
    )
