"""``vibsynth serve``'s follow: the input named by ``follow.device`` and the follower, as one control server.

:func:`create` builds (does not start) the input source (a PortAudio/JACK input, or a WAV file
paced by the output clock: :func:`vibsynth.engine.sources.open_input`) and the
:class:`~vibsynth.control.follow.follower.Follower`; :meth:`FollowService.start` opens the
input and starts the worker, and makes the follower findable by the OSC table and the studio
(:func:`vibsynth.control.follow.follower_of`).
"""

from __future__ import annotations

import logging

from vibsynth.control import follow as registry
from vibsynth.control.controller import Controller
from vibsynth.control.follow.follower import Follower
from vibsynth.dsp.basis import Basis
from vibsynth.engine.inputs import InputSource
from vibsynth.engine.sources import open_input
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["FollowService", "create"]

log = logging.getLogger(__name__)


class FollowService:
    """The follower started and stopped with the service (a :class:`~vibsynth.control.ControlServer`)."""

    name = "follow"

    def __init__(self, follower: Follower, *, prefix: str = "/vibsynth") -> None:
        self.follower = follower
        self.prefix = prefix.rstrip("/")

    def start(self) -> None:
        """Open the input and start following (raises DeviceError, InputError, ConfigError)."""
        self.follower.start()
        registry.attach(self.follower.controller, self.follower)
        for view in self.follower.routes():
            if view.kind == "source":
                from vibsynth.control import spatial

                if spatial.mixer_of(self.follower.controller) is None:
                    log.warning(
                        "follow: %s needs a layout (no touch sources without one); it drives nothing", view.label
                    )

    def stop(self) -> None:
        registry.detach(self.follower.controller, self.follower)
        self.follower.stop()

    def describe(self) -> str:
        f = self.follower
        targets = ", ".join(v.label for v in f.routes()) or "nothing"
        focus = f" focus {f.focus}" if f.follow.mode == "audio" else ""
        return (
            f"follow: {f.device_text()} -> {targets}, {f.follow.mode} mode{focus} "
            f"(gain with {self.prefix}/follow/gain DB)"
        )


def create(
    settings: VibsynthConfig, controller: Controller, *, basis: Basis | None = None, source: InputSource | None = None
) -> FollowService | None:
    """The follow service of the typed settings (``follow``, ``knobs``, ``audio``, ``clips``), or None when off.

    Parameters
    ----------
    settings : VibsynthConfig
    controller : Controller
        Its engine gives the rate and, for a file, the output clock that paces it.
    basis : Basis, optional
        The engine's basis (default: the shipped one).
    source : InputSource, optional
        Instead of the one ``follow.device`` names (tests, calibration).
    """
    follow = settings.follow
    if not follow.enabled:
        return None
    if basis is None:
        from vibsynth.formats.basis_file import default_basis

        basis = default_basis()
    engine = controller.engine
    if source is None:
        audio = settings.audio
        source = open_input(
            follow.device or "",
            fs=engine.fs,
            frame_clock=lambda: int(engine.frame_position),
            host_api=audio.host_api,
            block_size=audio.block_size,
        )
    follower = Follower(
        controller,
        source,
        follow,
        knobs=settings.knobs,
        basis=basis,
        transient_decay_ms=settings.clips.transient_decay_ms,
    )
    return FollowService(follower, prefix=settings.osc.prefix)
