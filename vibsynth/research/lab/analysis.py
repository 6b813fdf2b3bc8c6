"""Analysis of lab sessions, one or many participants: the paper's three results on one's own data.

* :func:`analyze_intensity` (experiment 1): per stimulus the geometric mean gain over
  participants, and the intensity model: the judged intensity (``-20 log10 gain``, dB re the
  reference) regressed on the 80-200 Hz band level, with R^2 (paper: 0.90), beside the same
  fit on the 10-1000 Hz level (paper: 0.07), and the spread of band levels before and after
  equalisation. :func:`write_equalised_set` stores the gains as a stimulus set.
* :func:`analyze_dissimilarity` (experiment 2): the weights ``w_j`` of
  ``D = sum_j w_j |T_aj - T_bj|`` by the paper's Lasso (:func:`~vibsynth.research.dissim.fit_dissimilarity_weights`),
  R^2 on held-out pairs, and the MDS map; the cross-validation uses fewer folds than 10 when
  there are few pairs (6 stimuli, 21 pairs: 8 folds).
* :func:`analyze_resynthesis` (experiment 3): mean and SD of the similarity of each version.

Sessions analysed together must share protocol and stimulus set (same ids).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.files import atomic_write_text
from vibsynth.formats.recordings import write_wav
from vibsynth.research.lab.protocol import VERSIONS
from vibsynth.research.lab.records import timestamp
from vibsynth.research.lab.session import Session, json_ready
from vibsynth.research.lab.stimuli import SET_FORMAT, SET_MANIFEST

if TYPE_CHECKING:
    from vibsynth.dsp.basis import Basis
    from vibsynth.research.dissim import DissimilarityFit, MdsMap, RatingsTable

__all__ = [
    "IntensityResult",
    "DissimilarityResult",
    "ResynthesisResult",
    "check_compatible",
    "analyze_intensity",
    "write_equalised_set",
    "folds_for",
    "analyze_dissimilarity",
    "analyze_resynthesis",
]


def check_compatible(sessions: Sequence[Session]) -> list[str]:
    """The stimulus ids shared by sessions analysed together (the first session's order).

    Raises
    ------
    InputError
        No sessions, or sessions of different protocols or stimulus sets.
    """
    if not sessions:
        raise InputError("no sessions to analyse")
    first = sessions[0]
    ids = list(first.meta["originals"] or [])
    for other in sessions[1:]:
        if other.protocol != first.protocol:
            raise InputError(
                f"{other.folder} is a {other.protocol} session, {first.folder} a {first.protocol} one: "
                "analyse one protocol at a time"
            )
        if list(other.meta["originals"] or []) != ids:
            raise InputError(
                f"{other.folder} and {first.folder} used different stimulus sets "
                f"({other.meta['set']['name']} vs {first.meta['set']['name']})"
            )
    return ids


def _pairwise_r(vectors: Sequence[NDArray[np.float64]]) -> tuple[float, float, int]:
    """Mean and SD of the Pearson r between every two vectors (finite entries common to both)."""
    rs = []
    for a, b in itertools.combinations(vectors, 2):
        keep = np.isfinite(a) & np.isfinite(b)
        if keep.sum() >= 3 and np.std(a[keep]) > 0 and np.std(b[keep]) > 0:
            rs.append(float(np.corrcoef(a[keep], b[keep])[0, 1]))
    if not rs:
        return math.nan, math.nan, 0
    return float(np.mean(rs)), float(np.std(rs)), len(rs)


def _linear_fit(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float, float]:
    """Least-squares line ``y = slope x + intercept`` and its R^2 (nan when x or y does not vary)."""
    if x.size < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan, math.nan, math.nan
    slope, intercept = np.polyfit(x, y, 1)
    pred = slope * x + intercept
    r2 = 1.0 - float(np.sum((y - pred) ** 2)) / float(np.sum((y - y.mean()) ** 2))
    return float(slope), float(intercept), r2


# --------------------------------------------------------------------------- experiment 1
@dataclass(frozen=True)
class IntensityResult:
    """Intensity equalisation over one or more sessions.

    Attributes
    ----------
    ids : list of str
        Stimuli.
    participants : list of str
        One per session.
    gains : ndarray, shape (n_sessions, n_stimuli)
        Each session's gain per stimulus (geometric mean of its repetitions; nan if not answered).
    mean_gain : ndarray, shape (n_stimuli,)
        Geometric mean over sessions (the paper's equalisation gains).
    level_db : ndarray, shape (n_stimuli,)
        80-200 Hz band level of each stimulus as played at gain 1.
    broadband_db : ndarray, shape (n_stimuli,)
        10-1000 Hz level at gain 1.
    judged_db : ndarray, shape (n_stimuli,)
        Perceived intensity re the reference: ``-20 log10(mean_gain)`` (the paper: "the inverse
        of the selected gains").
    equalised_db : ndarray, shape (n_stimuli,)
        Band level after equalisation: ``level_db + 20 log10(mean_gain)``.
    slope, intercept, r2 : float
        ``judged_db ~ slope * level_db + intercept`` (a perfect band-level equaliser: slope 1, R^2 1).
    r2_broadband : float
        The same fit on ``broadband_db``.
    participant_r, participant_r_sd : float
        Mean and SD of the Pearson r between every two participants' log gains (nan for one).
    reference_level_db : float
        The reference's band level (nan when the reference is a stimulus).
    """

    ids: list[str]
    participants: list[str]
    gains: NDArray[np.float64]
    mean_gain: NDArray[np.float64]
    level_db: NDArray[np.float64]
    broadband_db: NDArray[np.float64]
    judged_db: NDArray[np.float64]
    equalised_db: NDArray[np.float64]
    slope: float
    intercept: float
    r2: float
    r2_broadband: float
    participant_r: float
    participant_r_sd: float
    reference_level_db: float

    @property
    def level_sd_before(self) -> float:
        """SD of the stimuli's band levels before equalisation (dB)."""
        return float(np.nanstd(self.level_db))

    @property
    def level_sd_after(self) -> float:
        """SD of the band levels after equalisation (dB): smaller when participants equalise the 80-200 Hz band."""
        return float(np.nanstd(self.equalised_db))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return json_ready(
            {
                "protocol": "intensity",
                "ids": self.ids,
                "participants": self.participants,
                "gains": self.gains,
                "mean_gain": self.mean_gain,
                "level_db": self.level_db,
                "broadband_db": self.broadband_db,
                "judged_db": self.judged_db,
                "equalised_db": self.equalised_db,
                "slope": self.slope,
                "intercept": self.intercept,
                "r2": self.r2,
                "r2_broadband": self.r2_broadband,
                "level_sd_before": self.level_sd_before,
                "level_sd_after": self.level_sd_after,
                "participant_r": self.participant_r,
                "participant_r_sd": self.participant_r_sd,
                "reference_level_db": self.reference_level_db,
            }
        )


def analyze_intensity(sessions: Sequence[Session]) -> IntensityResult:
    """Gains and the intensity model over intensity sessions (complete or not).

    Raises
    ------
    InputError
        Sessions of another protocol or set, or no answered trial.
    """
    ids = check_compatible(sessions)
    if sessions[0].protocol != "intensity":
        raise InputError(f"{sessions[0].folder}: a {sessions[0].protocol} session, not an intensity one")
    index = {sid: k for k, sid in enumerate(ids)}
    gains = np.full((len(sessions), len(ids)), np.nan)
    for s, session in enumerate(sessions):
        logs: dict[int, list[float]] = {}
        for row in session.rows:
            logs.setdefault(index[row["stimulus"]], []).append(math.log(float(row["gain"])))
        for k, values in logs.items():
            gains[s, k] = math.exp(float(np.mean(values)))
    if not np.isfinite(gains).any():
        raise InputError("no answered trials to analyse")
    with np.errstate(all="ignore"):
        mean_gain = np.exp(np.nanmean(np.log(gains), axis=0))
    params = sessions[0].params()
    level = np.array([float(params[sid]["level_db"]) for sid in ids])
    broadband = np.array([float(params[sid]["broadband_db"]) for sid in ids])
    judged = -20.0 * np.log10(mean_gain)
    keep = np.isfinite(judged)
    slope, intercept, r2 = _linear_fit(level[keep], judged[keep])
    _, _, r2_broad = _linear_fit(broadband[keep], judged[keep])
    r_mean, r_sd, _ = _pairwise_r([np.log(g) for g in gains])
    reference = sessions[0].meta.get("reference")
    ref_level = float(params[reference]["level_db"]) if reference in params else math.nan
    return IntensityResult(
        ids=ids,
        participants=[s.participant for s in sessions],
        gains=gains,
        mean_gain=mean_gain,
        level_db=level,
        broadband_db=broadband,
        judged_db=judged,
        equalised_db=level + 20.0 * np.log10(mean_gain),
        slope=slope,
        intercept=intercept,
        r2=r2,
        r2_broadband=r2_broad,
        participant_r=r_mean,
        participant_r_sd=r_sd,
        reference_level_db=ref_level,
    )


def write_equalised_set(result: IntensityResult, sessions: Sequence[Session], folder: str | Path) -> Path:
    """Store the stimuli with their mean gains applied, as a stimulus set (a folder of WAVs + set.json).

    The folder is created (never an existing one); loading it gives a set marked
    ``equalised``, which the dissimilarity and resynthesis protocols play as it is.

    Parameters
    ----------
    result : IntensityResult
    sessions : sequence of Session
        The sessions of ``result`` (the stimuli are read from the first).
    folder : path-like

    Returns
    -------
    folder : pathlib.Path

    Raises
    ------
    InputError
        The folder exists or cannot be written, or a stimulus has no gain (not answered).
    """
    target = Path(folder).expanduser()
    missing = [sid for sid, g in zip(result.ids, result.mean_gain) if not np.isfinite(g)]
    if missing:
        raise InputError(f"no gain for {', '.join(missing[:5])}: finish the sessions before storing an equalised set")
    try:
        target.mkdir(parents=True)
    except FileExistsError:
        raise InputError(f"{target}: already exists; an equalised set is written to a new folder") from None
    except OSError as exc:
        raise InputError(f"{target}: cannot create ({exc.strerror or exc})") from None
    stimuli = sessions[0].stimuli()
    for sid, gain in zip(result.ids, result.mean_gain):
        s = stimuli[sid]
        write_wav(target / f"{sid}.wav", s.samples * float(gain), s.fs)
    manifest = {
        "format": SET_FORMAT,
        "equalised": True,
        "created": timestamp(datetime.now(timezone.utc)),
        "gains": {sid: float(g) for sid, g in zip(result.ids, result.mean_gain)},
        "sessions": [str(s.folder) for s in sessions],
        "participants": result.participants,
        "set": sessions[0].meta["set"],
    }
    atomic_write_text(target / SET_MANIFEST, json.dumps(json_ready(manifest), indent=1) + "\n")
    return target


# --------------------------------------------------------------------------- experiment 2
def folds_for(n_pairs: int, *, test_fraction: float = 0.2, max_folds: int = 10) -> int:
    """Cross-validation folds for ``n_pairs`` rated pairs: the paper's 10, fewer when the 80 %
    training set is small (each fold needs at least two pairs); 0 when no fit is possible."""
    n_test = max(2, int(round(test_fraction * n_pairs)))
    folds = min(max_folds, (n_pairs - n_test) // 2)
    return folds if folds >= 2 else 0


@dataclass(frozen=True)
class DissimilarityResult:
    """Dissimilarity ratings over one or more sessions and the paper's model fitted to them.

    Attributes
    ----------
    ids : list of str
    participants : list of str
    table : RatingsTable
        Mean rating per pair (over sessions), files = the first session's stimulus WAVs.
    scores : ndarray, shape (n_stimuli, n_components)
        T1..T8 of each stimulus.
    fit : DissimilarityFit or None
        Weights, held-out R^2 (``fit.r2_mean``), per-component R^2; None when no fit was possible.
    problem : str
        Why there is no fit or no map (empty when there are both).
    mds : MdsMap or None
        The 2-D map (needs every pair rated).
    self_mean, self_sd : float
        Ratings of stimuli against themselves (paper: 0.12, SD 0.07).
    participant_r, participant_r_sd : float
        Mean and SD of the Pearson r between every two participants' ratings.
    """

    ids: list[str]
    participants: list[str]
    table: RatingsTable
    scores: NDArray[np.float64]
    fit: DissimilarityFit | None
    problem: str
    mds: MdsMap | None
    self_mean: float
    self_sd: float
    participant_r: float
    participant_r_sd: float

    @property
    def largest_weight(self) -> int | None:
        """Index of the component with the largest weight (0 = V1), None without a fit."""
        return None if self.fit is None else int(np.argmax(self.fit.weights))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        out: dict[str, Any] = {
            "protocol": "dissimilarity",
            "ids": self.ids,
            "participants": self.participants,
            "pairs": [[self.ids[i], self.ids[j]] for i, j in self.table.pairs],
            "ratings": self.table.ratings,
            "counts": self.table.counts,
            "t1": self.scores[:, 0],
            "self_mean": self.self_mean,
            "self_sd": self.self_sd,
            "participant_r": self.participant_r,
            "participant_r_sd": self.participant_r_sd,
            "problem": self.problem,
            "fit": self.fit.to_dict() if self.fit is not None else None,
            "mds": None,
        }
        if self.mds is not None:
            out["mds"] = {
                "names": self.mds.names,
                "rated": self.mds.rated,
                "predicted": self.mds.predicted,
                "procrustes_rms": self.mds.procrustes_rms,
                "component_r": self.mds.component_r,
            }
        return json_ready(out)


def analyze_dissimilarity(
    sessions: Sequence[Session],
    *,
    basis: Basis,
    n_splits: int = 100,
    seed: int = 0,
    cv: int | None = None,
    components: bool = True,
) -> DissimilarityResult:
    """Mean ratings, the weights of the paper's model, its held-out R^2 and the MDS map.

    Parameters
    ----------
    sessions : sequence of Session
    basis : Basis
        Gives T1..T8 of the stimuli.
    n_splits, seed
        As :func:`~vibsynth.research.dissim.fit_dissimilarity_weights` (paper: 100 splits).
    cv : int, optional
        Folds; default :func:`folds_for` the number of pairs.
    components : bool
        Also the R^2 of each component alone and of the first i.

    Raises
    ------
    InputError
        Sessions of another protocol or set, no ratings, or a stimulus that cannot be analysed.
    """
    from vibsynth.dsp.dissimilarity import local_distances
    from vibsynth.research.dissim import RatingsTable, fit_dissimilarity_weights, mds_map, scores_for_files

    ids = check_compatible(sessions)
    if sessions[0].protocol != "dissimilarity":
        raise InputError(f"{sessions[0].folder}: a {sessions[0].protocol} session, not a dissimilarity one")
    index = {sid: k for k, sid in enumerate(ids)}
    sums: dict[tuple[int, int], list[float]] = {}
    per_session: list[dict[tuple[int, int], float]] = []
    for session in sessions:
        mine: dict[tuple[int, int], float] = {}
        for row in session.rows:
            a, b = index[row["stimulus_a"]], index[row["stimulus_b"]]
            key = (min(a, b), max(a, b))
            sums.setdefault(key, []).append(float(row["rating"]))
            mine[key] = float(row["rating"])
        per_session.append(mine)
    if not sums:
        raise InputError("no answered trials to analyse")
    keys = sorted(sums)
    files = [sessions[0].folder / "stimuli" / f"{sid}.wav" for sid in ids]
    table = RatingsTable(
        path=sessions[0].trials_path,
        files=files,
        pairs=np.array(keys, dtype=np.int64).reshape(-1, 2),
        ratings=np.array([float(np.mean(sums[k])) for k in keys]),
        counts=np.array([len(sums[k]) for k in keys], dtype=np.int64),
        n_rows=sum(len(v) for v in sums.values()),
    )
    scores = scores_for_files(files, basis=basis)
    self_ratings = [r for (i, j), values in sums.items() if i == j for r in values]
    all_keys = [(i, j) for i in range(len(ids)) for j in range(i, len(ids))]
    vectors = [np.array([m.get(k, np.nan) for k in all_keys]) for m in per_session]
    r_mean, r_sd, _ = _pairwise_r(vectors)
    fit = None
    problems = []
    folds = cv if cv is not None else folds_for(len(keys))
    if folds < 2:
        problems.append(f"{len(keys)} rated pairs are too few for a cross-validated fit")
    else:
        distances = local_distances(scores[table.pairs[:, 0]], scores[table.pairs[:, 1]])
        try:
            fit = fit_dissimilarity_weights(
                distances, table.ratings, n_splits=n_splits, seed=seed, cv=folds, components=components
            )
        except ParameterError as exc:
            problems.append(f"no fit: {exc}")
    mds = None
    try:
        mds = mds_map(table, scores, weights=fit.weights) if fit is not None else mds_map(table, scores)
    except InputError as exc:
        problems.append(f"no map: {exc}")
    return DissimilarityResult(
        ids=ids,
        participants=[s.participant for s in sessions],
        table=table,
        scores=scores,
        fit=fit,
        problem="; ".join(problems),
        mds=mds,
        self_mean=float(np.mean(self_ratings)) if self_ratings else math.nan,
        self_sd=float(np.std(self_ratings)) if self_ratings else math.nan,
        participant_r=r_mean,
        participant_r_sd=r_sd,
    )


# --------------------------------------------------------------------------- experiment 3
@dataclass(frozen=True)
class ResynthesisResult:
    """Similarity of each version to its original, over one or more sessions.

    Attributes
    ----------
    participants : list of str
    ratings : dict of str to ndarray
        Version -> every rating given to it (trials of every session).
    per_original : dict of str to dict of str to float
        Original -> version -> mean rating.
    """

    participants: list[str]
    ratings: dict[str, NDArray[np.float64]]
    per_original: dict[str, dict[str, float]] = field(default_factory=dict)

    def summary(self) -> list[dict[str, Any]]:
        """One row per version: ``version``, ``n``, ``mean``, ``sd``, ``median``."""
        rows = []
        for v in VERSIONS:
            r = self.ratings[v]
            rows.append(
                {
                    "version": v,
                    "n": int(r.size),
                    "mean": float(np.mean(r)) if r.size else math.nan,
                    "sd": float(np.std(r, ddof=1)) if r.size > 1 else math.nan,
                    "median": float(np.median(r)) if r.size else math.nan,
                }
            )
        return rows

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return json_ready(
            {
                "protocol": "resynthesis",
                "participants": self.participants,
                "summary": self.summary(),
                "per_original": self.per_original,
            }
        )


def analyze_resynthesis(sessions: Sequence[Session]) -> ResynthesisResult:
    """Ratings per version (mean, SD) over resynthesis sessions.

    Raises
    ------
    InputError
        Sessions of another protocol or set, or no answered trial.
    """
    check_compatible(sessions)
    if sessions[0].protocol != "resynthesis":
        raise InputError(f"{sessions[0].folder}: a {sessions[0].protocol} session, not a resynthesis one")
    ratings: dict[str, list[float]] = {v: [] for v in VERSIONS}
    by_original: dict[str, dict[str, list[float]]] = {}
    for session in sessions:
        for row in session.rows:
            mine = by_original.setdefault(row["original"], {v: [] for v in VERSIONS})
            for v in VERSIONS:
                value = float(row[f"rating_{v}"])
                ratings[v].append(value)
                mine[v].append(value)
    if not ratings[VERSIONS[0]]:
        raise InputError("no answered trials to analyse")
    return ResynthesisResult(
        participants=[s.participant for s in sessions],
        ratings={v: np.asarray(r) for v, r in ratings.items()},
        per_original={o: {v: float(np.mean(r)) for v, r in d.items()} for o, d in by_original.items()},
    )
