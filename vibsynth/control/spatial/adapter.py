"""The sources' adapter for ``vibsynth serve`` (contract of :mod:`vibsynth.control`): ``--layout`` and the mixer.

With a layout in the config (``layout: glove``, or positions), ``create`` builds the
:class:`~vibsynth.control.spatial.mixer.SourceMixer`; the OSC and MIDI adapters find it while
it runs (:func:`vibsynth.control.spatial.mixer_of`). Without a layout there are no sources
(their OSC messages get an error reply saying so).
"""

from __future__ import annotations

import argparse
import logging
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.spatial.mixer import SourceMixer
from vibsynth.control.spatial.sources import SourceDefaults, SourceTable
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.spatial import TextureSpectra
from vibsynth.settings.cli_args import flag_type
from vibsynth.settings.layouts import Layout, resolve_layout
from vibsynth.settings.models import bounds_of
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["add_arguments", "create", "build_mixer"]

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--layout NAME`` to the ``vibsynth serve`` parser."""
    group = parser.add_argument_group("spatial sources")
    group.add_argument(
        "--layout",
        type=flag_type("layout"),
        default=None,
        metavar="NAME",
        help="actuator layout for the touch sources: glove, vest-back, wristband or a user layout (default: layout)",
    )


def build_mixer(
    settings: VibsynthConfig,
    controller: Controller,
    layout: Layout,
    *,
    basis: Basis | None = None,
    presets: Any = None,
) -> SourceMixer:
    """A (not started) mixer for ``layout`` with the typed ``sources``, ``knobs`` and ``speed`` settings.

    Parameters
    ----------
    settings : VibsynthConfig
    controller : Controller
    layout : Layout
    basis : Basis, optional
        The engine's basis (default: the shipped one, as ``vibsynth serve`` uses).
    presets : object, optional
        Unused: presets are resolved through the controller's resolver.
    """
    if basis is None:
        from vibsynth.formats.basis_file import default_basis

        basis = default_basis()
    sources, knobs, speed = settings.sources, settings.knobs, settings.speed
    limits = controller.limits
    defaults = SourceDefaults(
        radius_m=sources.radius,
        rolloff=sources.rolloff,
        glide_s=sources.glide_ms / 1000.0,
        speed=sources.speed,
        speed_window_s=sources.speed_window_ms / 1000.0,
        radius_max_m=float(bounds_of("sources.radius")[1] or sources.radius),
        limits=limits,
    )
    return SourceMixer(
        controller,
        layout,
        TextureSpectra(basis, balance_min=limits.balance_min, balance_max=limits.balance_max),
        SourceTable(defaults, preset_resolver=controller.preset_resolver),
        update_s=sources.update_ms / 1000.0,
        schedule_capacity=sources.schedule_capacity,
        ceiling_db=knobs.ceiling_db,
        range_db=knobs.range_db,
        speed_curve=SpeedCurve(speed.curve, speed.balance_per_decade),
    )


def create(
    settings: VibsynthConfig, args: argparse.Namespace | None, controller: Controller, presets: Any = None
) -> SourceMixer | None:
    """Build (not start) the sources' mixer, or None without a layout (after one log line).

    Raises
    ------
    ConfigError
        The layout names a missing or broken layout file.
    """
    layout = resolve_layout(settings.layout)
    if layout is None:
        log.info("no layout in the config: touch sources are off (/vibsynth/source/... answers an error)")
        return None
    return build_mixer(settings, controller, layout, presets=presets)
