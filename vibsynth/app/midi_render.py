"""Rendering a MIDI file offline through the engine."""

from __future__ import annotations

import os
from typing import Any

import mido

from vibsynth.control.midi.bindings import MidiSettings
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import _one_line
from vibsynth.errors import ParameterError


def _knob_limits(data: dict[str, Any]) -> Any:
    from vibsynth.control.controller import KnobLimits

    knobs = data.get("knobs") or {}
    return KnobLimits(
        balance_min=float(knobs.get("balance_min", -3.5)), balance_max=float(knobs.get("balance_max", 3.5))
    )


def render_midi_file(
    path: str | os.PathLike[str],
    *,
    config: Any,
    basis: Any = None,
    seconds: float | None = None,
    presets: Any = None,
    block: int = 1024,
    engine: Any = None,
) -> tuple[Any, float]:
    """Render a MIDI file (CC automation and notes) offline through the live mapping.

    Every message is applied at its exact sample (``at_frame``), so the result
    is the same as playing the file into ``vibsynth serve`` with no jitter.

    Parameters
    ----------
    path : path
        Standard MIDI file (type 0 or 1; tempo changes honoured).
    config : vibsynth.settings.config.Config
    basis : Basis, optional
        Passed to :func:`vibsynth.app.service.build_engine`.
    seconds : float, optional
        Output length; default the file's length plus the release time and 0.25 s.
    presets : preset library, optional
        For program changes.
    block : int
        Render block size (frames).
    engine : Engine, optional
        A fresh engine to render with (tests, benchmarks); default
        ``vibsynth.app.service.build_engine(config, basis=basis)``.

    Returns
    -------
    samples : ndarray, float32, shape (frames, channels)
    fs : float

    Raises
    ------
    InputError
        The file cannot be read as MIDI.
    """
    import numpy as np

    from vibsynth.control.controller import Controller
    from vibsynth.errors import InputError

    try:
        midi_file = mido.MidiFile(str(path))
    except (OSError, ValueError, EOFError, KeyError, IndexError) as exc:
        raise InputError(f"{path}: not a readable MIDI file ({_one_line(exc)})") from None
    data = config.data
    if engine is None:
        from vibsynth.app.service import build_engine

        engine = build_engine(config, basis=basis)
    knobs = data.get("knobs") or {}
    controller = Controller(
        engine,
        limits=_knob_limits(data),
        initial_glide_s=float(knobs.get("glide_ms", 20.0)) / 1000.0,
        preset_resolver=getattr(presets, "get", None),
    )
    settings = MidiSettings.from_config(data, engine.channels)
    mapper = MidiMapper(controller, settings, presets=presets, source="midi-file")
    fs = float(engine.fs)
    events: list[tuple[int, mido.Message]] = []
    t = 0.0
    for msg in midi_file:  # iteration yields delta times in seconds (tempo applied)
        t += float(msg.time)
        if not msg.is_meta:
            events.append((int(round(t * fs)), msg))
    if seconds is None:
        seconds = t + settings.release_s + 0.25
    total = int(round(float(seconds) * fs))
    if total <= 0:
        raise ParameterError(f"render length must be positive, got {seconds!r} s")
    out = np.zeros((total, engine.channels), dtype=np.float32)
    i = 0
    pos = 0
    while pos < total:
        n = min(block, total - pos)
        while i < len(events) and events[i][0] < pos + n:
            mapper.handle(events[i][1], at_frame=max(events[i][0], pos))
            i += 1
        out[pos : pos + n] = engine.render(n)
        pos += n
    return out, fs
