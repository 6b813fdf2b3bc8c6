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
    "ClipError",
    "DeviceError",
    "CodecError",
    "MissingDependencyError",
    "EngineBusyError",
    "ScheduleFullError",
    "NoReplyError",
    "ServerError",
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


class ClipError(VibsynthError):
    """A haptic clip (file, import, export) is invalid or a clip name is unknown."""


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


class NoReplyError(VibsynthError, TimeoutError):
    """A running server was expected to answer and did not in time (:class:`vibsynth.Client`, ``vibsynth send``).

    Attributes
    ----------
    host : str
    port : int
    timeout : float
        Seconds waited.
    request : str
        The OSC address that asked (``""`` when not one request).
    """

    def __init__(self, host: str, port: int, timeout: float, request: str = "") -> None:
        self.host, self.port, self.timeout, self.request = host, int(port), float(timeout), request
        where = f"[{host}]" if ":" in host else host
        text = f"no reply from {where}:{self.port} within {self.timeout!r} s"
        if request:
            text += f" (to {request}; is `vibsynth serve` running there?)"
        super().__init__(text)

    def __reduce__(self) -> tuple[type[NoReplyError], tuple[str, int, float, str]]:
        return type(self), (self.host, self.port, self.timeout, self.request)


class ServerError(VibsynthError):
    """A server refused a request: it answered ``/vibsynth/error address message`` (nothing changed).

    Attributes
    ----------
    address : str
        The address the server complains about (what was sent).
    message : str
        The server's own explanation.
    errors : tuple of (str, str)
        Every ``(address, message)`` reported at once (``Client.sync`` may collect several).
    """

    def __init__(self, address: str, message: str, errors: tuple[tuple[str, str], ...] = ()) -> None:
        self.address, self.message = address, message
        self.errors = errors or ((address, message),)
        text = f"{address}: {message}"
        if len(self.errors) > 1:
            text += f" (and {len(self.errors) - 1} more error(s))"
        super().__init__(text)

    def __reduce__(self) -> tuple[type[ServerError], tuple[str, str, tuple[tuple[str, str], ...]]]:
        return type(self), (self.address, self.message, self.errors)
