"""A preset from a recording's analysis: the knobs that render it, clamped to the preset ranges, with provenance.

``vibsynth preset from-recording`` and the studio's recording panel make presets the same way:
the analysis (:func:`vibsynth.dsp.analysis.analyze`) gives the intensity knob under the
engine's mapping and the balance; values a preset cannot hold are clamped with a note, and the
provenance records where every number came from.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from vibsynth._version import __version__
from vibsynth.dsp.analysis import Analysis
from vibsynth.settings.presets import BALANCE_LIMIT, Preset

__all__ = ["RecordingPreset", "preset_from_analysis", "recording_digest"]


def recording_digest(data: bytes) -> str:
    """Short content hash (16 hex digits) of a recording file, kept in the provenance."""
    return hashlib.sha256(data).hexdigest()[:16]


@dataclass(frozen=True)
class RecordingPreset:
    """A preset made from a recording, and what had to be said about it.

    Attributes
    ----------
    preset : Preset
    warnings : tuple of str
        Values clamped to the preset ranges (the user should know).
    notes : tuple of str
        Facts worth a line (t1 outside the basis' database).
    """

    preset: Preset
    warnings: tuple[str, ...]
    notes: tuple[str, ...]


def preset_from_analysis(
    result: Analysis,
    *,
    name: str,
    recording: str,
    digest: str,
    basis_id: str,
    ceiling_db: float,
    range_db: float,
    created_by: str,
    description: str | None = None,
    glide_ms: float | None = None,
    program: int | None = None,
    tags: Sequence[str] = (),
    intensity_weighting: str | None = None,
) -> RecordingPreset:
    """The preset whose knobs render an analysed recording.

    Parameters
    ----------
    result : Analysis
        Of the recording, under the mapping ``ceiling_db`` / ``range_db``.
    name : str
    recording : str
        The recording's file name (provenance, description).
    digest : str
        :func:`recording_digest` of the file.
    basis_id : str
    ceiling_db, range_db : float
        The intensity mapping the analysis used.
    created_by : str
        What made it (``preset from-recording``, ``studio``).
    description, glide_ms, program, tags
        Preset fields (default description: ``From the recording <file>.``).
    intensity_weighting : str, optional
        What the analysis' level meant when not the paper's band (a calibrated profile's
        weighting, ``IntensityWeighting.describe()``): recorded as ``provenance.intensity``.

    Raises
    ------
    PresetError
        A field out of range (the name, tags, glide or program).
    """
    warnings: list[str] = []
    notes: list[str] = []
    intensity = min(1.0, max(0.0, result.intensity_knob))
    if intensity != result.intensity_knob:
        warnings.append(
            f"level {result.level_db:.1f} dB maps to intensity {result.intensity_knob:.3f}, outside [0, 1] with "
            f"knobs.ceiling_db = {ceiling_db:g} and range_db = {range_db:g}; clamped to {intensity:g}"
        )
    balance = result.balance
    if abs(balance) > BALANCE_LIMIT:
        clamped = math.copysign(BALANCE_LIMIT, balance)
        warnings.append(
            f"balance {balance:+.3f} is beyond the preset limit +-{BALANCE_LIMIT:g}; clamped to {clamped:+g}"
        )
        balance = clamped
    if result.outside_database:
        notes.append(f"t1 = {result.t1:.2f} lies outside the basis' database (represented, not clamped)")
    provenance: dict[str, Any] = {
        "recording": recording,
        "recording_sha256": digest,
        "fs_hz": float(result.fs),
        "duration_s": round(result.duration_s, 4),
        "level_db_80_200hz": round(result.level_db, 3),
        "intensity_mapping": {"ceiling_db": float(ceiling_db), "range_db": float(range_db)},
        "intensity_knob_unclamped": round(result.intensity_knob, 4),
        "t1": round(result.t1, 4),
        "balance": round(result.balance, 4),
        "scores": [round(float(s), 4) for s in result.scores],
        "non_stationarity_db": round(result.non_stationarity_db, 3),
        "outside_database": bool(result.outside_database),
        "basis_id": basis_id,
        "created_by": f"vibsynth {__version__} ({created_by})",
    }
    if intensity_weighting is not None:
        provenance["intensity"] = intensity_weighting
    preset = Preset(
        name=name,
        intensity=round(intensity, 4),
        balance=round(balance, 4),
        description=description or f"From the recording {recording}.",
        glide_ms=glide_ms,
        program=program,
        tags=tuple(tags),
        provenance=provenance,
    )
    return RecordingPreset(preset, tuple(warnings), tuple(notes))
