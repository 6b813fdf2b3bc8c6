"""Control adapters (OSC, MIDI) that translate outside messages into :class:`Controller` calls.

Each adapter module listed in :data:`ADAPTER_MODULES` provides two functions the
service calls without knowing the protocol:

``add_arguments(parser)``
    add its ``vibsynth serve`` flags (e.g. ``--osc-port``) to an argparse parser;
``create(settings, args, controller, presets) -> ControlServer | None``
    build (not start) its server from the typed settings (a
    :class:`~vibsynth.settings.models_config.VibsynthConfig`, built once by the command
    line; the adapter reads its own sections and hands on typed sections, never the
    dict form) and flags, or return None when it is disabled or unavailable (after
    logging one line saying why).

A :class:`ControlServer` has ``name``, ``start()``, ``stop()`` and ``describe()``
(one line for the start-up banner, e.g. ``OSC on udp://127.0.0.1:9570``).
"""

from __future__ import annotations

import importlib
import logging
from types import ModuleType
from typing import Protocol

__all__ = ["ControlServer", "ADAPTER_MODULES", "adapter_modules"]

log = logging.getLogger(__name__)

ADAPTER_MODULES = (
    "vibsynth.control.spatial.adapter",
    "vibsynth.control.clips.adapter",
    "vibsynth.control.osc.adapter",
    "vibsynth.control.midi.adapter",
)


class ControlServer(Protocol):
    name: str

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def describe(self) -> str: ...


def adapter_modules() -> list[ModuleType]:
    """The adapter modules that exist in this installation."""
    modules = []
    for name in ADAPTER_MODULES:
        try:
            modules.append(importlib.import_module(name))
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
    return modules
