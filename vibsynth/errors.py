"""The one exception family of vibsynth.

Every error that bad input can cause derives from :class:`VibsynthError`, so the
command line and the servers catch one type, print one clear line and keep the
last good state.
"""

from __future__ import annotations

__all__ = [
    "VibsynthError",
    "ParameterError",
    "InputError",
    "ConfigError",
    "PresetError",
    "DeviceError",
    "CodecError",
    "MissingDependencyError",
    "EngineBusyError",
    "ScheduleFullError",
]


class VibsynthError(Exception):
    """Base class of every error raised on purpose by vibsynth."""


class ParameterError(VibsynthError, ValueError):
    """A function or knob received a value outside its domain (NaN, range, shape)."""


class InputError(VibsynthError):
    """A recording or data file cannot be used (missing, unreadable, silent, too short)."""


class ConfigError(VibsynthError):
    """A configuration file or setting is invalid; the message names file, key and range."""


class PresetError(VibsynthError):
    """A preset file is invalid or a preset name is unknown."""


class DeviceError(VibsynthError):
    """An audio or MIDI device cannot be opened or has failed."""


class CodecError(VibsynthError):
    """An encoded parameter-trajectory file is corrupt, truncated or of an unknown version."""


class MissingDependencyError(VibsynthError, ImportError):
    """An optional dependency (scikit-learn, matplotlib: ``pip install 'vibsynth[research]'``) is missing."""


class EngineBusyError(VibsynthError):
    """The engine's command hand-off is full: the command was refused and nothing changed."""


class ScheduleFullError(EngineBusyError):
    """Too many timetagged commands are waiting: the cap (``engine.schedule_capacity``) was reached."""
