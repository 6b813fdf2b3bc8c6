"""vibsynth: real-time haptic texture synthesis from intensity and high/low frequency balance.

The science (Bernard, Thoret, Huloux & Ystad, "The high/low frequency balance drives
the perception of noisy vibrations") lives in :mod:`vibsynth.dsp`; the real-time
engine in :mod:`vibsynth.engine`; OSC and MIDI adapters in :mod:`vibsynth.control`.

The public API (docs/python.md) is the names below. They are imported on first use
(PEP 562), so ``import vibsynth`` loads neither numpy nor scipy:

======================  ==========================================================
``analyze``             intensity, balance and spectrum of a recording (array or file)
``synthesize``          noise with an exact 30-band spectrum (closed form)
``render``              a stationary texture through the real-time engine, offline
``follow``              knob trajectories that follow a sound or vibration (docs/follow.md)
``Engine``, ``Basis``   the engine and the spectral basis
``load_config``         the effective configuration (defaults, user file, environment)
``Preset``              a named texture
``Client``              drive a running ``vibsynth serve`` over OSC
``VibsynthError``       base class of every error raised on purpose
``__version__``         the version (written in ``vibsynth/_version.py`` only; pyproject.toml reads it)
======================  ==========================================================
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from vibsynth._version import __version__

if TYPE_CHECKING:
    from vibsynth.app.api import analyze, follow, render
    from vibsynth.app.client import Client
    from vibsynth.dsp.basis import Basis
    from vibsynth.dsp.synthesis import synthesize
    from vibsynth.engine.engine import Engine
    from vibsynth.errors import VibsynthError
    from vibsynth.settings.config import load_config
    from vibsynth.settings.presets import Preset

__all__ = [
    "Engine",
    "Basis",
    "analyze",
    "synthesize",
    "render",
    "follow",
    "load_config",
    "Preset",
    "Client",
    "VibsynthError",
    "__version__",
]

# public name -> module that defines it
_LAZY = {
    "Engine": "vibsynth.engine.engine",
    "Basis": "vibsynth.dsp.basis",
    "analyze": "vibsynth.app.api",
    "synthesize": "vibsynth.dsp.synthesis",
    "render": "vibsynth.app.api",
    "follow": "vibsynth.app.api",
    "load_config": "vibsynth.settings.config",
    "Preset": "vibsynth.settings.presets",
    "Client": "vibsynth.app.client",
    "VibsynthError": "vibsynth.errors",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'vibsynth' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
