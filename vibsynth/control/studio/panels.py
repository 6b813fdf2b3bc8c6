"""The studio's panels with routes or threads of their own, installed on a server."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vibsynth.control.studio.follow import FollowPanel
from vibsynth.control.studio.presets import PresetsPanel
from vibsynth.control.studio.recording import RecordingPanel
from vibsynth.control.studio.spectrum import SpectrumModel, SpectrumPanel
from vibsynth.control.studio.status import StatusPanel
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB

__all__ = ["install_panels"]


def install_panels(server: Any, servers: Sequence[Any] = (), settings: Any = None) -> None:
    """Add the status, spectrum, presets, recording and follow panels to ``server`` (a StudioServer, not started).

    The spectrum uses the shipped basis (the one ``vibsynth serve`` builds its bank from) and
    the engine's intensity mapping. ``settings`` (the typed VibsynthConfig) lets the follow
    panel start or switch the follow input.
    """
    from vibsynth.formats.basis_file import default_basis

    engine = server.controller.engine
    basis = default_basis()
    ceiling_db = float(getattr(engine, "ceiling_db", DEFAULT_CEILING_DB))
    range_db = float(getattr(engine, "range_db", DEFAULT_RANGE_DB))
    presets = PresetsPanel(server, server.library)
    server.plugins += [
        StatusPanel(server, servers),
        SpectrumPanel(server, SpectrumModel(basis, fs=float(engine.fs), ceiling_db=ceiling_db, range_db=range_db)),
        presets,
        RecordingPanel(server, presets, basis, ceiling_db, range_db),
        FollowPanel(server, settings, servers),
    ]
