"""The ``clips:`` config section, typed: the user's clip folder, hot reload, and how AHAP and Meta
``.haptic`` values map onto the two knobs when a clip is imported (and back when exported).

Added to the root model (:class:`~vibsynth.settings.models_config.VibsynthConfig`) with one line;
``docs/config.md``'s table of this section is generated from it.
"""

from __future__ import annotations

from pydantic import ValidationInfo, model_validator

from vibsynth.settings.fields import Section, cross_problem, setting
from vibsynth.settings.values import KNOB_BALANCE_LIMIT

__all__ = ["MAX_DECAY_MS", "Clips"]

_LIMIT = KNOB_BALANCE_LIMIT
#: Longest transient decay in a clip: a transient is a short burst; a slower one is a keyframe ramp.
MAX_DECAY_MS = 2000.0
_INVERTED = "(sharper must mean brighter, and export inverts the mapping)"


class Clips(Section):
    """``clips:``: the user's clip folder, hot reload, and the AHAP / Meta import mapping."""

    user_dir: str | None = setting(None, "null = the platform data folder's clips/", allowed="a folder path or null")
    watch: bool = setting(True, "hot reload while serving")
    intensity_exponent: float = setting(
        1.0,
        "import: knob intensity = (AHAP HapticIntensity or Meta amplitude) ** exponent; export inverts it",
        ge=0.1,
        le=10,
    )
    sharpness_0_balance: float | None = setting(
        None,
        "import: balance at AHAP HapticSharpness / Meta frequency 0; null = knobs.balance_min",
        unit="(knob units)",
        ge=-_LIMIT,
        le=_LIMIT,
    )
    sharpness_half_balance: float = setting(
        0.0,
        "import: balance at sharpness / frequency 0.5 (linear between the three points)",
        unit="(knob units)",
        ge=-_LIMIT,
        le=_LIMIT,
    )
    sharpness_1_balance: float | None = setting(
        None,
        "import: balance at sharpness / frequency 1; null = knobs.balance_max",
        unit="(knob units)",
        ge=-_LIMIT,
        le=_LIMIT,
    )
    transient_decay_ms: float = setting(
        40.0,
        "import: decay of a transient made from an AHAP HapticTransient or a Meta emphasis point",
        unit="ms",
        gt=0,
        le=MAX_DECAY_MS,
    )

    @model_validator(mode="after")
    def _increasing(self, info: ValidationInfo) -> Clips:
        """Rules between keys (skipped with context ``{"cross_checks": False}``, as the root's)."""
        if isinstance(info.context, dict) and not info.context.get("cross_checks", True):
            return self
        low, mid, high = self.sharpness_0_balance, self.sharpness_half_balance, self.sharpness_1_balance
        if low is not None and not low < mid:
            raise cross_problem(
                f"clips.sharpness_0_balance = {low:g} must be below clips.sharpness_half_balance = {mid:g} "
                + _INVERTED,
                "clips.sharpness_0_balance",
                "clips.sharpness_half_balance",
            )
        if high is not None and not mid < high:
            raise cross_problem(
                f"clips.sharpness_1_balance = {high:g} must be above clips.sharpness_half_balance = {mid:g} "
                + _INVERTED,
                "clips.sharpness_1_balance",
                "clips.sharpness_half_balance",
            )
        return self
