"""The tracker's parameters, their limits and the two modes' defaults.

The limits are module constants so the settings model (``settings/models_follow.py``) declares
the same ranges. Every value is checked here too: the tracker is usable without the settings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

from vibsynth.errors import ParameterError

__all__ = [
    "MODES",
    "FOCUSES",
    "Mode",
    "Focus",
    "GAIN_DB_LIMITS",
    "GATE_DB_LIMITS",
    "RANGE_DB_LIMITS",
    "TIME_MS_LIMITS",
    "HOP_MS_LIMITS",
    "TrackerParams",
    "default_params",
]

Mode = Literal["vibration", "audio"]
Focus = Literal["all", "effects", "bass", "beat"]
MODES: tuple[Mode, ...] = ("vibration", "audio")
FOCUSES: tuple[Focus, ...] = ("all", "effects", "bass", "beat")

GAIN_DB_LIMITS = (-60.0, 60.0)
GATE_DB_LIMITS = (-200.0, 0.0)
RANGE_DB_LIMITS = (6.0, 120.0)
#: attack, release, level and balance windows (ms)
TIME_MS_LIMITS = (1.0, 10000.0)
HOP_MS_LIMITS = (1.0, 10000.0)


@dataclass(frozen=True)
class TrackerParams:
    """What a :class:`~vibsynth.dsp.follow.tracker.Tracker` does with its input.

    Attributes
    ----------
    mode : {"vibration", "audio"}
        ``vibration``: the input is a vibration; the paper's model per window, output band level =
        input band level + ``gain_db``. ``audio``: program audio; loudness, brightness and onsets
        are mapped (docs/follow.md).
    focus : {"all", "effects", "bass", "beat"}
        Audio mode: what shakes. Ignored in vibration mode.
    gain_db : float
        Added to the tracked level before it becomes the intensity knob.
    gate_db : float
        Input level (vibration: 80-200 Hz band dB; audio: loudness, LUFS-like) below which the
        output is silent (intensity 0); 2 dB of hysteresis.
    range_db : float
        Audio mode: input loudness span mapped onto the whole intensity knob range (loudness
        ``top_db - range_db`` -> knob 0+, ``top_db`` -> knob 1).
    top_db : float
        Audio mode: loudness (LUFS-like, fast) that reaches intensity knob 1 at gain 0.
    attack_ms, release_ms : float
        Audio mode: level ballistics (dB domain).
    level_ms : float
        Vibration mode: the 80-200 Hz level's window (boxcar over the band-filtered power).
    balance_ms : float
        Window of the balance (vibration: 30-band spectrum, the paper's 100 ms; audio: spectral
        tilt smoothing).
    hop_ms : float
        Frame period (live: a few ms; the offline codec uses 50 ms).
    transients : bool
        Detect onsets (``onset_strength`` stays 0 when off).
    """

    mode: Mode = "vibration"
    focus: Focus = "all"
    gain_db: float = 0.0
    gate_db: float = -120.0
    range_db: float = 40.0
    top_db: float = -10.0
    attack_ms: float = 5.0
    release_ms: float = 10.0
    level_ms: float = 10.0
    balance_ms: float = 100.0
    hop_ms: float = 2.7
    transients: bool = True

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParameterError(f"follow mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.focus not in FOCUSES:
            raise ParameterError(f"follow focus must be one of {', '.join(FOCUSES)}, got {self.focus!r}")
        checks = (
            ("gain_db", self.gain_db, GAIN_DB_LIMITS),
            ("gate_db", self.gate_db, GATE_DB_LIMITS),
            ("range_db", self.range_db, RANGE_DB_LIMITS),
            ("top_db", self.top_db, GATE_DB_LIMITS),
            ("attack_ms", self.attack_ms, TIME_MS_LIMITS),
            ("release_ms", self.release_ms, TIME_MS_LIMITS),
            ("level_ms", self.level_ms, TIME_MS_LIMITS),
            ("balance_ms", self.balance_ms, TIME_MS_LIMITS),
            ("hop_ms", self.hop_ms, HOP_MS_LIMITS),
        )
        for name, value, (lo, hi) in checks:
            if not isinstance(value, (int, float)) or not math.isfinite(value) or not lo <= value <= hi:
                raise ParameterError(f"follow {name} must be a number in [{lo:g}, {hi:g}], got {value!r}")

    def with_(self, **changes: object) -> TrackerParams:
        """A copy with some values changed (validated)."""
        return replace(self, **changes)  # type: ignore[arg-type]


def default_params(mode: Mode = "vibration", focus: Focus = "all") -> TrackerParams:
    """The documented defaults of a mode (audio: a -60 LUFS gate; vibration: only silence gates).

    Parameters
    ----------
    mode : {"vibration", "audio"}
    focus : {"all", "effects", "bass", "beat"}

    Returns
    -------
    params : TrackerParams
    """
    if mode == "audio":
        return TrackerParams(mode="audio", focus=focus, gate_db=-60.0)
    return TrackerParams(mode=mode, focus=focus)
