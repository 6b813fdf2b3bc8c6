"""vibsynth: real-time haptic texture synthesis from intensity and high/low frequency balance.

The science (Bernard, Thoret, Huloux & Ystad, "The high/low frequency balance drives
the perception of noisy vibrations") lives in :mod:`vibsynth.dsp`; the real-time
engine in :mod:`vibsynth.engine`; OSC and MIDI adapters in :mod:`vibsynth.control`.
"""

from __future__ import annotations

__version__ = "0.1.0"

from vibsynth.errors import VibsynthError  # noqa: E402

__all__ = ["__version__", "VibsynthError"]
