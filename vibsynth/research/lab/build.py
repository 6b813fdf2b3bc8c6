"""From what the experimenter picked to a session folder ready to run: the one way sessions are made.

:func:`new_session` prepares the stimulus set (:func:`~vibsynth.research.lab.stimuli.prepare`),
adds what the protocol plays besides it (the intensity reference; the resynthesis versions),
draws the plan from the seed (:mod:`~vibsynth.research.lab.orders`) and creates the folder
(:meth:`~vibsynth.research.lab.session.Session.create`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, knob_to_level_db
from vibsynth.errors import ParameterError
from vibsynth.limits import VOICE_GAIN_MAX
from vibsynth.research.lab.orders import Plan, make_plan
from vibsynth.research.lab.protocol import LabParameters, check_participant, check_protocol, check_seed
from vibsynth.research.lab.session import Session
from vibsynth.research.lab.staircase import TRIALS_PER_SINE, check_method, staircase_plan
from vibsynth.research.lab.stimuli import (
    NORMALISE_MODES,
    SINE_MAX_HZ,
    SINE_MIN_HZ,
    SINE_REFERENCE_HZ,
    Stimulus,
    StimulusSet,
    load_sines,
    prepare,
    reference_noise,
    resynthesis_versions,
)

if TYPE_CHECKING:
    from vibsynth.dsp.basis import Basis

__all__ = [
    "REFERENCES",
    "SINE_GAIN_RANGE",
    "SINE_HEADROOM_DB",
    "SessionRequest",
    "default_normalise",
    "sine_amplitude",
    "sine_parameters",
    "sine_reference_hz",
    "new_session",
]

#: The gain range of an iso-intensity (sines) session: +-24 dB around the reference's drive, the
#: buffer voices' whole gain (``VOICE_GAIN_MAX``): a skin curve spans ~20-30 dB over 10-1000 Hz.
SINE_GAIN_RANGE = (1.0 / VOICE_GAIN_MAX, float(VOICE_GAIN_MAX))
#: A sine at the largest gain peaks this far below the limiter's ceiling (the limiter never acts).
SINE_HEADROOM_DB = 1.0

#: The intensity reference: white noise at the stimuli's median 80-200 Hz level (default), white
#: noise of the stimuli's standard deviation (the paper's literal reference), or a stimulus id.
REFERENCES = ("noise", "noise-std")


@dataclass(frozen=True)
class SessionRequest:
    """What the experimenter asks for.

    Attributes
    ----------
    protocol : str
    participant : str
    seed : int
    parameters : LabParameters
    normalise : str or None
        ``std``, ``band`` or ``none``; None = :func:`default_normalise`.
    reference : str
        Intensity: ``noise``, ``noise-std`` or a stimulus id; with a sine set, ``sine:F`` (a
        reference sine of F Hz), and ``noise`` (the default) means a :data:`SINE_REFERENCE_HZ` sine.
    repetitions : int
        Intensity: adjustments per stimulus.
    method : str
        Intensity on sines: ``adjustment`` (the slider), ``staircase`` (1-up/1-down on
        stronger/weaker answers) or ``staircase-2d1u`` (:mod:`~vibsynth.research.lab.staircase`).
    staircase_trials : int
        Trials of each sine's staircase.
    """

    protocol: str
    participant: str
    seed: int
    parameters: LabParameters = LabParameters()
    normalise: str | None = None
    reference: str = "noise"
    repetitions: int = 1
    method: str = "adjustment"
    staircase_trials: int = TRIALS_PER_SINE

    def __post_init__(self) -> None:
        check_method(self.method)
        check_protocol(self.protocol)
        check_participant(self.participant)
        check_seed(self.seed)
        if self.normalise is not None and self.normalise not in NORMALISE_MODES:
            raise ParameterError(
                f"unknown normalisation {self.normalise!r}; choose one of {', '.join(NORMALISE_MODES)}"
            )


def default_normalise(protocol: str, stimulus_set: StimulusSet) -> str:
    """The paper's preparation: ``std`` before the intensity equalisation; otherwise ``none`` for a set
    equalised by participants and ``band`` (iso-intense by the intensity model) for any other."""
    if protocol == "intensity":
        return "std"
    return "none" if stimulus_set.equalised else "band"


def sine_amplitude(gain_max: float, limiter_ceiling: float) -> float:
    """The peak of every sine of a set: at ``gain_max`` it stays :data:`SINE_HEADROOM_DB` under the ceiling."""
    if not (gain_max > 0 and 0 < limiter_ceiling <= 1):
        raise ParameterError(f"need gain_max > 0 and a limiter ceiling in (0, 1], got {gain_max}, {limiter_ceiling}")
    return limiter_ceiling * 10.0 ** (-SINE_HEADROOM_DB / 20.0) / gain_max


def sine_parameters(protocol: str, parameters: LabParameters) -> LabParameters:
    """The parameters of a session on sines: the intensity protocol over :data:`SINE_GAIN_RANGE`.

    Raises
    ------
    ParameterError
        Another protocol than intensity.
    """
    if protocol != "intensity":
        raise ParameterError("a set of sines is for iso-intensity curves: use the intensity protocol")
    return replace(parameters, gain_min=SINE_GAIN_RANGE[0], gain_max=SINE_GAIN_RANGE[1])


def sine_reference_hz(reference: str) -> float:
    """The reference sine's frequency: ``noise`` (the default) gives :data:`SINE_REFERENCE_HZ`, ``sine:F`` F."""
    if reference in REFERENCES:
        return SINE_REFERENCE_HZ
    head, _, tail = reference.partition(":")
    try:
        freq = float(tail) if head == "sine" and len(tail) <= 20 else math.nan
    except ValueError:
        freq = math.nan
    if not SINE_MIN_HZ <= freq <= SINE_MAX_HZ:
        raise ParameterError(
            f"reference {reference[:40]!r}: a sine set is matched to a reference sine: give sine:F with F in "
            f"{SINE_MIN_HZ:g}-{SINE_MAX_HZ:g} Hz (default {SINE_REFERENCE_HZ:g})"
        )
    return freq


def new_session(
    root: str | os.PathLike[str],
    request: SessionRequest,
    stimulus_set: StimulusSet,
    *,
    basis: Basis,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
    folder: str | os.PathLike[str] | None = None,
    limiter_ceiling: float | None = None,
) -> Session:
    """Prepare the set, make the plan, create the session folder; the session is open for appending.

    A set of sines (iso-intensity curves) is played as generated, every sine and the reference
    sine at one drive level, with the gain range :data:`SINE_GAIN_RANGE`, levelled so that no
    sine at any allowed gain reaches the limiter (:func:`sine_amplitude`).

    Parameters
    ----------
    root : path-like
        The sessions folder.
    request : SessionRequest
    stimulus_set : StimulusSet
        As loaded (:func:`~vibsynth.research.lab.stimuli.load_set`).
    basis : Basis
    ceiling_db, range_db : float
        The intensity knob mapping (the set's median stimulus plays at ``parameters.level``).
    folder : path-like, optional
        An explicit session folder (refused if it exists).
    limiter_ceiling : float, optional
        The engine's limiter ceiling (``knobs.limiter_ceiling``; default: its default).

    Raises
    ------
    ParameterError
        The protocol needs more stimuli, an unknown reference.
    InputError
        A stimulus cannot be analysed; the folder cannot be created.
    """
    protocol = check_protocol(request.protocol)
    if stimulus_set.kind == "sines":
        p, prepared, played, reference, set_info = _sines(request, stimulus_set, basis, limiter_ceiling)
    elif request.method != "adjustment":
        raise ParameterError("the staircase matches sines to a reference sine: use a set of sines (sines[:F1,F2,...])")
    else:
        p = request.parameters
        minimum = 2 if protocol == "dissimilarity" else 1
        if len(stimulus_set.stimuli) < minimum:
            raise ParameterError(f"the {protocol} protocol needs at least {minimum} stimuli")
        mode = request.normalise or default_normalise(protocol, stimulus_set)
        level = knob_to_level_db(p.level, ceiling_db=ceiling_db, range_db=range_db)
        prepared = prepare(stimulus_set, mode=mode, level_db=level, basis=basis)  # type: ignore[arg-type]
        played = list(prepared.stimuli)
        reference = None
        if protocol == "intensity":
            reference = _reference(prepared, request, basis)
            if reference.id == "reference":
                played.append(reference)
        elif protocol == "resynthesis":
            for index, original in enumerate(prepared.stimuli):
                played += [
                    v
                    for name, v in resynthesis_versions(original, basis=basis, seed=request.seed, index=index).items()
                    if name != "O"
                ]
        set_info = {
            "name": stimulus_set.name,
            "kind": stimulus_set.kind,
            "equalised": stimulus_set.equalised,
            "normalise": mode,
            "level_db": level,
        }
    if request.method != "adjustment":
        plan: Plan = staircase_plan(
            prepared.ids, seed=request.seed, gain_min=p.gain_min, gain_max=p.gain_max, trials=request.staircase_trials
        )
    else:
        plan = make_plan(
            protocol,
            prepared.ids,
            seed=request.seed,
            familiarisation=p.familiarisation_pairs,
            gain_min=p.gain_min,
            gain_max=p.gain_max,
            repetitions=request.repetitions,
        )
    return Session.create(
        root,
        protocol=protocol,
        participant=request.participant,
        seed=request.seed,
        stimuli=played,
        plan=plan,
        parameters=p,
        set_info=set_info,
        basis_id=basis.id,
        reference=reference.id if reference is not None else None,
        originals=prepared.ids,
        folder=folder,
        method=request.method,
    )


def _reference(prepared: StimulusSet, request: SessionRequest, basis: Basis) -> Stimulus:
    seconds = request.parameters.stimulus_s
    if request.reference in REFERENCES:
        match = "level" if request.reference == "noise" else "std"
        return reference_noise(prepared.stimuli, seconds=seconds, seed=request.seed, basis=basis, match=match)
    chosen = prepared.by_id().get(request.reference)
    if chosen is None:
        raise ParameterError(
            f"reference {request.reference!r}: give noise, noise-std or one of the set's stimuli "
            f"({', '.join(prepared.ids[:8])}{'...' if len(prepared.ids) > 8 else ''})"
        )
    return chosen


def _sines(
    request: SessionRequest, stimulus_set: StimulusSet, basis: Basis, limiter_ceiling: float | None
) -> tuple[LabParameters, StimulusSet, list[Stimulus], Stimulus, dict[str, Any]]:
    """A sine set's parameters, sines, what plays (sines + reference sine), reference and set info."""
    p = sine_parameters(request.protocol, request.parameters)
    if limiter_ceiling is None:
        from vibsynth.settings.models_config import Knobs

        limiter_ceiling = float(Knobs().limiter_ceiling)
    amplitude = sine_amplitude(p.gain_max, limiter_ceiling)
    fs = stimulus_set.stimuli[0].fs
    freqs = [float(s.params["frequency_hz"]) for s in stimulus_set.stimuli]
    reference_hz = sine_reference_hz(request.reference)
    sines = load_sines(freqs, fs=fs, seconds=p.stimulus_s, amplitude=amplitude, basis=basis)
    ref = load_sines([reference_hz], fs=fs, seconds=p.stimulus_s, amplitude=amplitude, basis=basis).stimuli[0]
    reference = Stimulus("reference", ref.samples, fs, {**ref.params, "source": "reference sine"})
    set_info = {
        "name": stimulus_set.name,
        "kind": "sines",
        "equalised": False,
        "normalise": "none",
        "reference_hz": reference_hz,
        "amplitude": amplitude,
        "limiter_ceiling": limiter_ceiling,
        "headroom_db": SINE_HEADROOM_DB,
    }
    return p, sines, [*sines.stimuli, reference], reference, set_info
