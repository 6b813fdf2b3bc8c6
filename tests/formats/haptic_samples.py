"""AHAP and Meta ``.haptic`` documents for tests, built from the published formats."""

from __future__ import annotations

import json
from typing import Any


def event(t, kind="HapticContinuous", duration=None, intensity=None, sharpness=None, **extra) -> dict[str, Any]:
    """An AHAP pattern entry ``{"Event": {...}}`` (parameters left out when None)."""
    params = []
    if intensity is not None:
        params.append({"ParameterID": "HapticIntensity", "ParameterValue": intensity})
    if sharpness is not None:
        params.append({"ParameterID": "HapticSharpness", "ParameterValue": sharpness})
    body = {"Time": t, "EventType": kind, "EventParameters": params, **extra}
    if duration is not None:
        body["EventDuration"] = duration
    return {"Event": body}


def curve(pid: str, t: float, points) -> dict[str, Any]:
    """An AHAP pattern entry ``{"ParameterCurve": {...}}`` from (time, value) points."""
    return {
        "ParameterCurve": {
            "ParameterID": pid,
            "Time": t,
            "ParameterCurveControlPoints": [{"Time": a, "ParameterValue": v} for a, v in points],
        }
    }


def ahap(*entries, **top) -> str:
    """AHAP text of a pattern."""
    return json.dumps({"Version": 1.0, "Metadata": {"Project": "test"}, "Pattern": list(entries), **top})


def meta(amplitude, frequency=None, **top) -> str:
    """Meta ``.haptic`` text of an amplitude envelope (and a frequency envelope)."""
    envelopes = {"amplitude": amplitude}
    if frequency is not None:
        envelopes["frequency"] = frequency
    doc = {
        "version": {"major": 1, "minor": 0, "patch": 0},
        "metadata": {"editor": "Meta Haptics Studio", "tags": ["test"], "description": "a test"},
        "signals": {"continuous": {"envelopes": envelopes}},
        **top,
    }
    return json.dumps(doc)


#: A spring (after Apple's example): a transient, then a continuous event faded out by an intensity curve.
SPRING = ahap(
    event(0.0, "HapticTransient", intensity=0.8, sharpness=0.4),
    event(0.015, duration=0.25, intensity=0.8, sharpness=0.4),
    curve("HapticIntensityControl", 0.015, [(0, 1), (0.25, 0.0)]),
    Metadata={"Description": "a spring"},
)
