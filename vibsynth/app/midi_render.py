"""Rendering a MIDI file offline through the live MIDI mapping and the engine (:mod:`vibsynth.app.render`)."""

from __future__ import annotations

import heapq
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import mido
import numpy as np
from numpy.typing import NDArray

from vibsynth.app.render import DEFAULT_BLOCK, ArrayCollector, Cue, RenderResult, Sink, render
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.midi.bindings import MidiSettings
from vibsynth.control.midi.clipnotes import ClipNotes
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import _one_line
from vibsynth.engine.engine import Engine
from vibsynth.errors import InputError, ParameterError
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["MidiRender", "prepare_midi_render", "render_midi_file", "render_midi_to"]


@dataclass
class MidiRender:
    """A MIDI file ready to render: the engine, its timeline and the length.

    Attributes
    ----------
    engine : Engine
        With the controller and mapper that the timeline's cues call.
    timeline : iterator of Cue
        One cue per (non-meta) message at its frame; each calls ``mapper.handle(msg, at_frame=...)``.
        Generated while rendering (nothing per message is stored), so it can be rendered once.
    frames : int
        Output length.
    """

    engine: Engine
    timeline: Iterator[Cue]
    frames: int

    @property
    def fs(self) -> float:
        return float(self.engine.fs)


def prepare_midi_render(
    path: str | os.PathLike[str],
    *,
    settings: VibsynthConfig | None = None,
    basis: Any = None,
    seconds: float | None = None,
    presets: Any = None,
    engine: Engine | None = None,
    clips: Any = None,
) -> MidiRender:
    """Read a MIDI file and set up the engine, controller and mapper that play it.

    Notes of the ``midi_clips`` map play their clips, as ``vibsynth serve`` does (a clip
    player on the render's controller, ticked every block).

    Parameters
    ----------
    path : path-like
        Standard MIDI file (type 0 or 1; tempo changes honoured).
    settings : VibsynthConfig, optional
        The typed settings (``knobs``, ``midi``, ``midi_clips``...); default: the packaged
        defaults (:func:`~vibsynth.settings.config.default_settings`).
    basis : Basis, optional
        Passed to :func:`vibsynth.app.service.build_engine`.
    seconds : float, optional
        Output length; default the file's length plus the release time and 0.25 s.
    presets : preset library, optional
        For program changes.
    engine : Engine, optional
        A fresh engine to render with (tests, benchmarks); default
        ``vibsynth.app.service.build_engine(settings, basis=basis)``.
    clips : ClipLibrary, optional
        For the clip notes (default: the config's clip library).

    Raises
    ------
    InputError
        The file cannot be read as MIDI.
    ParameterError
        A non-positive length.
    """
    from vibsynth.control.controller import Controller

    if settings is None:
        from vibsynth.settings.config import default_settings

        settings = default_settings()
    try:
        midi_file = mido.MidiFile(str(path))
    except (OSError, ValueError, EOFError, KeyError, IndexError) as exc:
        raise InputError(f"{path}: not a readable MIDI file ({_one_line(exc)})") from None
    if engine is None:
        from vibsynth.app.service import build_engine

        engine = build_engine(settings, basis=basis)
    controller = Controller.for_knobs(engine, settings.knobs, preset_resolver=getattr(presets, "get", None))
    midi = MidiSettings.from_settings(settings.midi, engine.channels, fade_ms=settings.knobs.mute_fade_ms)
    player = _clip_player(settings, controller, clips)
    clip_notes = None
    if player is not None:
        clip_notes = ClipNotes.from_settings(settings.midi_clips, controller, player=lambda: player)
    mapper = MidiMapper(controller, midi, presets=presets, source="midi-file", clip_notes=clip_notes)
    fs = float(engine.fs)
    if seconds is None:
        t = 0.0
        for msg in midi_file:  # delta times in seconds (tempo applied), summed as the timeline does
            t += float(msg.time)
        seconds = t + midi.release_s + 0.25
    frames = int(round(float(seconds) * fs))
    if frames <= 0:
        raise ParameterError(f"render length must be positive, got {seconds!r} s")
    timeline: Iterator[Cue] = _timeline(midi_file, mapper, fs)
    if player is not None:  # the clip player's ticks, every block, between the messages
        ticks = (Cue(f, _tick(player)) for f in range(0, frames, DEFAULT_BLOCK))
        timeline = heapq.merge(timeline, ticks, key=lambda cue: cue.frame)
    return MidiRender(engine, timeline, frames)


def _clip_player(settings: VibsynthConfig, controller: Any, library: Any) -> ClipPlayer | None:
    """A clip player for the notes of ``midi_clips`` (None when the settings map no note)."""
    if not settings.midi_clips.notes:
        return None
    if library is None:
        from vibsynth.settings.clips import load_clip_library

        library = load_clip_library(settings)
    return ClipPlayer(controller, library.get, start_margin_frames=0)


def _tick(player: ClipPlayer) -> Callable[[int], object]:
    return lambda at_frame: player.tick()


def _timeline(midi_file: mido.MidiFile, mapper: MidiMapper, fs: float) -> Iterator[Cue]:
    """A cue per non-meta message, at the frame of its time (seconds, tempo applied), made as needed."""
    t = 0.0
    for msg in midi_file:  # iteration yields delta times in seconds (tempo applied)
        t += float(msg.time)
        if not msg.is_meta:
            yield Cue(int(round(t * fs)), _handler(mapper, msg))


def _handler(mapper: MidiMapper, msg: mido.Message) -> Callable[[int], object]:
    return lambda at_frame: mapper.handle(msg, at_frame=at_frame)


def render_midi_to(
    job: MidiRender,
    sink: Sink,
    *,
    block: int = DEFAULT_BLOCK,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """Render a prepared MIDI file into ``sink`` (a streaming WAV writer, a collector).

    Every message is applied at its exact sample (``at_frame``), so the result is the
    same as playing the file into ``vibsynth serve`` with no jitter.
    """
    return render(job.engine, job.frames, sink, timeline=job.timeline, block=block, progress=progress)


def render_midi_file(
    path: str | os.PathLike[str],
    *,
    settings: VibsynthConfig | None = None,
    basis: Any = None,
    seconds: float | None = None,
    presets: Any = None,
    block: int = DEFAULT_BLOCK,
    engine: Engine | None = None,
    clips: Any = None,
) -> tuple[NDArray[np.float32], float]:
    """Render a MIDI file (CC automation and notes) offline into an array.

    For short renders; stream long ones to a file with :func:`prepare_midi_render`,
    :func:`render_midi_to` and a :class:`~vibsynth.formats.wav_stream.WavStreamWriter`.
    Parameters as :func:`prepare_midi_render`; ``block`` is the render block (frames).

    Returns
    -------
    samples : ndarray, float32, shape (frames, channels)
    fs : float

    Raises
    ------
    InputError
        The file cannot be read as MIDI.
    ParameterError
        A non-positive length, or one too long to hold in memory
        (:data:`~vibsynth.app.render.MAX_COLLECT_BYTES`).
    """
    job = prepare_midi_render(
        path, settings=settings, basis=basis, seconds=seconds, presets=presets, engine=engine, clips=clips
    )
    result = render_midi_to(job, ArrayCollector(job.frames, job.engine.channels), block=block)
    return result.output, job.fs
