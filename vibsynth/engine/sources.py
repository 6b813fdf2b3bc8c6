"""Which input source a ``--follow`` argument (``follow.device``) names.

:func:`open_input` sits above the sources it chooses between (:mod:`vibsynth.engine.inputs`: a
device or a sound file; :mod:`vibsynth.engine.monitor`: what the system plays, built on a device
input), so none of them imports another round a circle.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from vibsynth.engine.inputs import FileInput, InputSource, SoundDeviceInput
from vibsynth.engine.monitor import MonitorInput, is_monitor_spec
from vibsynth.formats.sound_reader import SOUND_SUFFIXES

__all__ = ["open_input"]


def open_input(
    spec: str,
    *,
    fs: float,
    frame_clock: Callable[[], int],
    loop: bool = False,
    **device_options: Any,
) -> InputSource:
    """The input source ``spec`` names (not opened).

    A :class:`~vibsynth.engine.inputs.FileInput` when ``spec`` names a sound file (``.wav``,
    ``.flac``, ``.ogg``... or any file that exists), a :class:`~vibsynth.engine.monitor.MonitorInput`
    for ``monitor`` (what the system plays), else a :class:`~vibsynth.engine.inputs.SoundDeviceInput`.

    Parameters
    ----------
    spec : str
        A sound file, ``monitor``, or ``DEVICE[:CH,...]`` (``""``: the default input).
    fs : float
        The engine's rate.
    frame_clock : callable
        Frames the output has rendered (paces a file).
    loop : bool
        A file starts again at its end.
    **device_options
        To :class:`~vibsynth.engine.inputs.SoundDeviceInput` (``host_api``, ``block_size``, ...).

    Raises
    ------
    InputError
        A sound file that cannot be read.
    ParameterError
        A malformed device spec.
    """
    text = str(spec)
    if text.lower().endswith(SOUND_SUFFIXES) or Path(text).is_file():
        return FileInput(text, fs=fs, frame_clock=frame_clock, loop=loop)
    if is_monitor_spec(text):
        return MonitorInput(fs=fs, **device_options)
    return SoundDeviceInput(text, fs=fs, **device_options)
