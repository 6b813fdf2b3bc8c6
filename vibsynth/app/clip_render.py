"""Rendering a haptic clip offline: its compiled knob moves as the one renderer's timeline (:mod:`vibsynth.app.render`).

The clip is compiled by the same timeline compiler the live player uses
(:class:`~vibsynth.control.clips.timeline.ClipTimeline`), starting at frame 0, and each
move becomes a :class:`~vibsynth.app.render.Cue` for the real-time engine: the file is
what ``vibsynth serve`` plays for ``/vibsynth/play``, sample for sample, without jitter.
When the clip ends every channel glides back to the configured initial knobs (the knob
state of a fresh server) over ``knobs.glide_ms``. The moves are generated while rendering,
so a long loop streams in constant memory.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.app.render import DEFAULT_BLOCK, ArrayCollector, Cue, render
from vibsynth.control.clips.timeline import ClipLike, ClipTimeline, check_play_args
from vibsynth.control.controller import KnobLimits
from vibsynth.engine.commands import SetKnob
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["TAIL_S", "ClipRender", "prepare_clip_render", "render_clip"]

#: Silence kept after the glide back at the end of a clip.
TAIL_S = 0.05


@dataclass
class ClipRender:
    """A clip ready to render.

    Attributes
    ----------
    engine : Engine
    timeline : iterator of Cue
        The compiled moves, then the glide back to the initial knobs (consumed once).
    frames : int
        Output length.
    clip_timeline : ClipTimeline
        The compiled clip (its ``end_frame``, positions).
    """

    engine: Engine
    timeline: Iterator[Cue]
    frames: int
    clip_timeline: ClipTimeline

    @property
    def fs(self) -> float:
        return float(self.engine.fs)


def prepare_clip_render(
    clip: str | ClipLike,
    *,
    settings: VibsynthConfig | None = None,
    basis: Any = None,
    gain: float = 1.0,
    rate: float = 1.0,
    loops: int = 1,
    seconds: float | None = None,
    library: Any = None,
    engine: Engine | None = None,
) -> ClipRender:
    """Compile a clip and set up the engine that renders it.

    Parameters
    ----------
    clip : str or Clip
        A clip name (looked up in ``library``, default the config's clip library) or a clip.
    settings : VibsynthConfig, optional
        The typed settings; default: the packaged defaults. Its knob limits, glide and initial
        knobs apply.
    basis : Basis, optional
        For the engine's bank (default: the shipped basis).
    gain, rate, loops
        As ``/vibsynth/play`` (:func:`~vibsynth.control.clips.timeline.check_play_args`).
    seconds : float, optional
        Output length; default the clip's length (loops and rate applied) plus the glide
        back and :data:`TAIL_S`. Required when ``loops`` is 0 (until stopped).
    library : ClipLibrary, optional
    engine : Engine, optional
        A fresh engine (tests); default :func:`vibsynth.app.service.build_engine`.

    Raises
    ------
    UnknownClipError
        No clip of that name (with the library's did-you-mean).
    ParameterError
        Gain, rate or loops out of range; ``loops`` 0 without ``seconds``; a non-positive length.
    """
    if settings is None:
        from vibsynth.settings.config import default_settings

        settings = default_settings()
    if isinstance(clip, str):
        if library is None:
            from vibsynth.settings.clips import load_clip_library

            library = load_clip_library(settings)
        resolved: ClipLike = library.get(clip)
    else:
        resolved = clip
    gain, rate, loops = check_play_args(gain, rate, loops)
    if loops == 0 and seconds is None:
        raise ParameterError("loops 0 repeats the clip until stopped: give a length (--seconds)")
    knobs = settings.knobs
    limits = KnobLimits(balance_min=knobs.balance_min, balance_max=knobs.balance_max)
    if engine is None:
        from vibsynth.app.service import build_engine

        engine = build_engine(settings, basis=basis)
    fs = float(engine.fs)
    compiled = ClipTimeline(
        resolved,
        fs=fs,
        start_frame=0,
        gain=gain,
        rate=rate,
        loops=loops,
        balance_limits=(limits.balance_min, limits.balance_max),
        glide_max_s=limits.glide_max_s,
    )
    glide_s = knobs.glide_ms / 1000.0
    if seconds is None:
        assert compiled.end_frame is not None
        frames = compiled.end_frame + int(round((glide_s + TAIL_S) * fs))
    else:
        frames = int(round(float(seconds) * fs))
    if frames <= 0:
        raise ParameterError(f"render length must be positive, got {seconds!r} s")
    back = (("balance", knobs.initial_balance), ("intensity", knobs.initial_intensity))
    return ClipRender(engine, _cues(compiled, back, glide_s), frames, compiled)


def _cues(compiled: ClipTimeline, back: tuple[tuple[str, float], ...], glide_s: float) -> Iterator[Cue]:
    for move in compiled.moves():
        yield Cue(move.frame, SetKnob(move.knob, move.value, glide_s=move.glide_s))
    if compiled.end_frame is not None:
        for knob, value in back:
            yield Cue(compiled.end_frame, SetKnob(knob, float(value), glide_s=glide_s))  # type: ignore[arg-type]


def render_clip(
    clip: str | ClipLike, *, block: int = DEFAULT_BLOCK, **kwargs: Any
) -> tuple[NDArray[np.float32], float]:
    """Render a clip into an array (short renders; stream long ones with :func:`prepare_clip_render`).

    Parameters as :func:`prepare_clip_render`; ``block`` is the render block (frames).

    Returns
    -------
    samples : ndarray, float32, shape (frames, channels)
    fs : float
    """
    job = prepare_clip_render(clip, **kwargs)
    result = render(
        job.engine, job.frames, ArrayCollector(job.frames, job.engine.channels), timeline=job.timeline, block=block
    )
    return result.output, job.fs
