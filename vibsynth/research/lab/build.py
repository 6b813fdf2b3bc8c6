"""From what the experimenter picked to a session folder ready to run: the one way sessions are made.

:func:`new_session` prepares the stimulus set (:func:`~vibsynth.research.lab.stimuli.prepare`),
adds what the protocol plays besides it (the intensity reference; the resynthesis versions),
draws the plan from the seed (:mod:`~vibsynth.research.lab.orders`) and creates the folder
(:meth:`~vibsynth.research.lab.session.Session.create`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, knob_to_level_db
from vibsynth.errors import ParameterError
from vibsynth.research.lab.orders import Plan, make_plan
from vibsynth.research.lab.protocol import LabParameters, check_participant, check_protocol, check_seed
from vibsynth.research.lab.session import Session
from vibsynth.research.lab.stimuli import (
    NORMALISE_MODES,
    Stimulus,
    StimulusSet,
    prepare,
    reference_noise,
    resynthesis_versions,
)

if TYPE_CHECKING:
    from vibsynth.dsp.basis import Basis

__all__ = ["REFERENCES", "SessionRequest", "default_normalise", "new_session"]

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
        Intensity: ``noise``, ``noise-std`` or a stimulus id.
    repetitions : int
        Intensity: adjustments per stimulus.
    """

    protocol: str
    participant: str
    seed: int
    parameters: LabParameters = LabParameters()
    normalise: str | None = None
    reference: str = "noise"
    repetitions: int = 1

    def __post_init__(self) -> None:
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


def new_session(
    root: str | os.PathLike[str],
    request: SessionRequest,
    stimulus_set: StimulusSet,
    *,
    basis: Basis,
    ceiling_db: float = DEFAULT_CEILING_DB,
    range_db: float = DEFAULT_RANGE_DB,
    folder: str | os.PathLike[str] | None = None,
) -> Session:
    """Prepare the set, make the plan, create the session folder; the session is open for appending.

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

    Raises
    ------
    ParameterError
        The protocol needs more stimuli, an unknown reference.
    InputError
        A stimulus cannot be analysed; the folder cannot be created.
    """
    protocol = check_protocol(request.protocol)
    p = request.parameters
    minimum = 2 if protocol == "dissimilarity" else 1
    if len(stimulus_set.stimuli) < minimum:
        raise ParameterError(f"the {protocol} protocol needs at least {minimum} stimuli")
    mode = request.normalise or default_normalise(protocol, stimulus_set)
    level = knob_to_level_db(p.level, ceiling_db=ceiling_db, range_db=range_db)
    prepared = prepare(stimulus_set, mode=mode, level_db=level, basis=basis)  # type: ignore[arg-type]
    played: list[Stimulus] = list(prepared.stimuli)
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
    plan: Plan = make_plan(
        protocol,
        prepared.ids,
        seed=request.seed,
        familiarisation=p.familiarisation_pairs,
        gain_min=p.gain_min,
        gain_max=p.gain_max,
        repetitions=request.repetitions,
    )
    set_info = {
        "name": stimulus_set.name,
        "kind": stimulus_set.kind,
        "equalised": stimulus_set.equalised,
        "normalise": mode,
        "level_db": level,
    }
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
