"""The ``lab:`` section: the perception lab's defaults, which are the paper's parameters (docs/lab.md)."""

from __future__ import annotations

from functools import cache

from pydantic import ValidationInfo, model_validator

from vibsynth.limits import VOICE_GAIN_MAX
from vibsynth.settings.fields import Section, cross_problem, setting

__all__ = ["Lab", "lab_range"]


class Lab(Section):
    """``lab:``: the perception lab (sessions folder and the protocols' defaults, from the paper)."""

    folder: str | None = setting(
        None, "where sessions are written; null = the platform data folder's lab/", allowed="a folder path or null"
    )
    stimulus_s: float = setting(1.0, "duration of each stimulus (paper: 1 s)", unit="s", ge=0.5, le=10)
    gap_ms: float = setting(
        500.0, "silence between the two stimuli of a pair (paper: 500 ms)", unit="ms", ge=0, le=5000
    )
    familiarisation_pairs: int = setting(
        30, "random pairs played before the dissimilarity test, not saved (paper: 30); 0 = none", ge=0, le=1000
    )
    # A stimulus plays as a buffer voice at its gain: the engine's voice gain limit bounds both.
    gain_min: float = setting(0.2, "lowest gain of the intensity equalisation (paper: 0.2)", gt=0, le=VOICE_GAIN_MAX)
    gain_max: float = setting(5.0, "highest gain of the intensity equalisation (paper: 5)", gt=0, le=VOICE_GAIN_MAX)
    level: float = setting(
        0.75,
        "intensity knob at which a stimulus set's median stimulus plays (its 80-200 Hz level through knobs.*)",
        unit="(knob units)",
        gt=0,
        le=1,
    )

    @model_validator(mode="after")
    def _gain_range(self, info: ValidationInfo) -> Lab:
        """gain_min < gain_max (skipped with context ``{"cross_checks": False}``: one layer at a time)."""
        context = info.context if isinstance(info.context, dict) else {}
        if context.get("cross_checks", True) and self.gain_min >= self.gain_max:
            raise cross_problem(
                f"lab.gain_max = {self.gain_max:g} must be above lab.gain_min = {self.gain_min:g}",
                "lab.gain_max",
                "lab.gain_min",
            )
        return self


@cache
def lab_range(name: str) -> tuple[float, float, bool]:
    """``(low, high, low_open)`` of a numeric ``lab:`` key, from :class:`Lab` (its one definition).

    The research layer checks its session parameters (``LabParameters``) with it.
    """
    schema = Lab.model_json_schema()["properties"][name]
    low_open = "exclusiveMinimum" in schema
    return float(schema["exclusiveMinimum" if low_open else "minimum"]), float(schema["maximum"]), low_open
