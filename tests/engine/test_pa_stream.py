"""Importing python-sounddevice (vibsynth/engine/pa_stream.py): what is missing is one clear DeviceError."""

from __future__ import annotations

import sys

import pytest

from vibsynth.engine.pa_stream import import_sounddevice
from vibsynth.errors import DeviceError


class _Refuse:
    """A meta path finder standing in for a machine without PortAudio, or without the package."""

    def __init__(self, error: Exception) -> None:
        self.error = error

    def find_spec(self, name, path=None, target=None):
        if name == "sounddevice":
            raise self.error
        return None


@pytest.mark.parametrize(
    ("error", "expected"),
    [
        # what sounddevice itself raises when libportaudio2 is not installed
        (OSError("PortAudio library not found"), "PortAudio is not available (PortAudio library not found); install"),
        (ModuleNotFoundError("No module named 'sounddevice'"), "the sounddevice package is not installed"),
    ],
)
def test_a_missing_portaudio_or_package_is_one_device_error(monkeypatch, error, expected):
    monkeypatch.delitem(sys.modules, "sounddevice", raising=False)
    monkeypatch.setattr(sys, "meta_path", [_Refuse(error), *sys.meta_path])
    with pytest.raises(DeviceError) as caught:
        import_sounddevice()
    assert expected in str(caught.value) and "\n" not in str(caught.value)
    assert caught.value.__cause__ is None and caught.value.__suppress_context__
