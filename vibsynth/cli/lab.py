"""``vibsynth lab``: the perception lab (issue 17) from the command line.

``vibsynth lab`` alone serves and opens the studio's Lab page, where sessions are run; the
actions list sessions, show the trial order a seed gives, analyse finished (or unfinished)
sessions, one participant or many, and store intensity gains as an equalised stimulus set.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from typing import Any

from vibsynth.cli._common import add_basis_argument, basis_from_args, integer_in
from vibsynth.cli._table import Column, add_format_argument, emit, output_format
from vibsynth.errors import InputError

ORDER = 58

HELP = """\
The paper's three experiments on your actuator, stimuli and participants (docs/lab.md):
  intensity      adjust each stimulus' gain (0.2-5) to feel as intense as a reference
  dissimilarity  rate all pairs (self-pairs included), stimulus - 500 ms - stimulus, 0..1
  resynthesis    rate 5 versions (O, S1, S1:8, S2:8, M) of each original against it, 0..1
Without an action: run the engine like `vibsynth serve` (same flags) and open the studio on
its Lab tab, where sessions are set up, run and analysed (the URL ends in #lab).
Sessions are folders under lab.folder (default: the platform data folder's lab/), named
PARTICIPANT-PROTOCOL-DATE-TIME; give a session by its folder or that name.
Stimulus sets: 'presets', 'presets:NAME,NAME', 'renders', 'renders:N' or a folder of WAVs;
'sines' or 'sines:F1,F2,...' (8-12 frequencies, 10-1000 Hz) for iso-intensity curves
(intensity protocol, matched to a 250 Hz reference sine).
"""

_seed = integer_in(0, 2**64 - 1, what="seed")
#: A session given by name (PARTICIPANT-PROTOCOL-DATE-TIME), looked for in the sessions folder.
SESSION_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,200}")


def register(subparsers: argparse._SubParsersAction) -> None:
    from vibsynth.cli import serve
    from vibsynth.settings.config import add_config_arguments

    p = subparsers.add_parser(
        "lab",
        help="perception lab: run the paper's experiments, list and analyse sessions",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    serve.add_arguments(p)
    p.set_defaults(func=run_open, open_browser=True, open_fragment="#lab")
    sub = p.add_subparsers(dest="lab_command", metavar="ACTION")

    ls = sub.add_parser("sessions", help="list the sessions (progress, protocol, participant)")
    ls.add_argument("--folder", type=Path, help="sessions folder (default: lab.folder from the config)")
    add_format_argument(ls)
    add_config_arguments(ls)
    ls.set_defaults(func=run_sessions)

    plan = sub.add_parser(
        "plan",
        help="the trial order a seed gives (nothing is played or written)",
        description="Prints the trials of a protocol for a stimulus set and a seed: the same seed gives the "
        "same order. Familiarisation pairs (dissimilarity) are marked and are not saved when run.",
    )
    plan.add_argument("protocol", choices=("intensity", "dissimilarity", "resynthesis"))
    plan.add_argument(
        "--stimuli",
        required=True,
        metavar="SET",
        help="presets, presets:A,B, renders[:N], sines[:F1,F2,...] or a folder",
    )
    plan.add_argument("--seed", type=_seed, default=0, help="seed of the order (default 0)")
    plan.add_argument(
        "--familiarisation",
        type=integer_in(0, 1000),
        default=None,
        metavar="N",
        help="pairs (default lab.familiarisation_pairs: 30)",
    )
    plan.add_argument(
        "--method",
        choices=("adjustment", "staircase", "staircase-2d1u"),
        default="adjustment",
        help="sines: a gain slider (default) or a staircase per sine on stronger/weaker answers (16 trials each)",
    )
    add_format_argument(plan)
    add_config_arguments(plan)
    plan.set_defaults(func=run_plan)

    an = sub.add_parser(
        "analyze",
        help="analyse sessions of one protocol and stimulus set (one participant or many)",
        description="intensity: mean gains and the intensity model (judged intensity vs 80-200 Hz level, R^2); "
        "dissimilarity: the weights w_j (non-negative Lasso, folds fewer than 10 for small sets), R^2 on held-out "
        "pairs and the MDS map; resynthesis: mean and SD of each version's rating; intensity on sines: the "
        "iso-intensity curve (each participant, mean and SD in dB re the reference sine; --format csv; --plot; "
        "--profile adds it in acceleration). Unfinished sessions are analysed as far as they go.",
    )
    an.add_argument("sessions", nargs="+", metavar="SESSION", help="session folders or names")
    an.add_argument("--folder", type=Path, help="sessions folder for names (default: lab.folder)")
    an.add_argument(
        "--splits", type=integer_in(1, 1000), default=100, help="dissimilarity: random 80/20 splits (default 100)"
    )
    an.add_argument("--seed", type=int, default=0, help="dissimilarity: seed of the splits and folds (default 0)")
    an.add_argument(
        "--plot",
        type=Path,
        metavar="FILE.png",
        help="dissimilarity: write the MDS map; sines: the iso-intensity curve (needs matplotlib)",
    )
    an.add_argument(
        "--profile",
        metavar="NAME",
        help="sines: an actuator profile (measured response) to give the curve in acceleration too",
    )
    add_format_argument(an)
    add_basis_argument(an)
    add_config_arguments(an)
    an.set_defaults(func=run_analyze)

    eq = sub.add_parser(
        "equalise",
        help="store intensity sessions' mean gains as an equalised stimulus set (a new folder of WAVs)",
        description="Applies each stimulus' geometric mean gain over the sessions (the paper's equalisation) and "
        "writes the stimuli with set.json to a new folder; the dissimilarity and resynthesis protocols play such "
        "a set as it is.",
    )
    eq.add_argument("sessions", nargs="+", metavar="SESSION", help="intensity session folders or names")
    eq.add_argument("-o", "--output", type=Path, required=True, metavar="FOLDER", help="new folder for the set")
    eq.add_argument("--folder", type=Path, help="sessions folder for names (default: lab.folder)")
    add_config_arguments(eq)
    eq.set_defaults(func=run_equalise)


# --------------------------------------------------------------------------- helpers
def _root(args: argparse.Namespace) -> Path:
    from vibsynth.research.lab.session import sessions_root
    from vibsynth.settings.config import settings_from_args

    if getattr(args, "folder", None):
        return Path(args.folder).expanduser()
    return sessions_root(settings_from_args(args).lab)


def _open_sessions(args: argparse.Namespace) -> list[Any]:
    """The sessions named on the command line (folders, or names under the sessions folder), read only."""
    from vibsynth.research.lab.session import Session

    root = _root(args)
    out = []
    for name in args.sessions:
        path = Path(name).expanduser()
        if not path.is_dir() and SESSION_NAME.fullmatch(name) and (root / name).is_dir():
            path = root / name
        if not path.is_dir():
            raise InputError(f"{name}: no such session (neither a folder nor a session in {root})")
        out.append(Session.open(path))
    return out


def _num(digits: int) -> Any:
    return lambda v: "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}f}"


# --------------------------------------------------------------------------- actions
def run_open(args: argparse.Namespace) -> int:
    """``vibsynth lab``: ``vibsynth serve`` (same flags) and open the studio on its Lab tab."""
    from vibsynth.cli import serve
    from vibsynth.errors import ParameterError

    if args.no_studio:
        raise ParameterError("vibsynth lab --no-studio: the Lab page is part of the studio (use vibsynth serve)")
    return serve.run(args)


def run_sessions(args: argparse.Namespace) -> int:
    from vibsynth.research.lab.session import list_sessions

    root = _root(args)
    sessions, problems = list_sessions(root)
    for problem in problems:
        print(f"vibsynth: warning: {problem}", file=sys.stderr)
    fmt = output_format(args)
    rows = [s.to_dict() for s in sessions]
    for row in rows:
        row["progress"] = f"{row['done']}/{row['total']}"
        row["name"] = Path(row["folder"]).name
    if fmt == "table" and not rows:
        print(f"no sessions in {root}")
        return 0
    columns = [
        Column("name", "session", name=True),
        Column("protocol", "protocol"),
        Column("participant", "participant"),
        Column("set", "stimuli", name=True),
        Column("progress", "done"),
        Column("seed", "seed"),
        Column("created", "created (UTC)"),
    ]
    if fmt != "table":
        columns = [
            Column(k, k)
            for k in ("folder", "protocol", "participant", "set", "done", "total", "complete", "seed", "created")
        ]
    emit(rows, columns, fmt)
    return 0


def run_plan(args: argparse.Namespace) -> int:
    from vibsynth.errors import ParameterError
    from vibsynth.research.lab.build import sine_parameters
    from vibsynth.research.lab.orders import make_plan
    from vibsynth.research.lab.protocol import LabParameters
    from vibsynth.research.lab.staircase import staircase_plan
    from vibsynth.research.lab.stimuli import REFERENCE_RATE_HZ, load_set
    from vibsynth.settings.config import settings_from_args
    from vibsynth.settings.library import load_library

    settings = settings_from_args(args)
    params = LabParameters.from_settings(settings.lab, familiarisation_pairs=args.familiarisation)
    library = load_library(settings)
    stimuli = load_set(
        args.stimuli,
        presets=library.presets,
        fs=REFERENCE_RATE_HZ,
        seconds=params.stimulus_s,
        seed=args.seed,
        basis=basis_from_args(args),
    )
    if stimuli.kind == "sines":
        params = sine_parameters(args.protocol, params)
    if args.method != "adjustment":
        if stimuli.kind != "sines":
            raise ParameterError("--method staircase matches sines to a reference sine: use --stimuli sines[:F1,...]")
        plan = staircase_plan(stimuli.ids, seed=args.seed, gain_min=params.gain_min, gain_max=params.gain_max)
    else:
        plan = make_plan(
            args.protocol,
            stimuli.ids,
            seed=args.seed,
            familiarisation=params.familiarisation_pairs,
            gain_min=params.gain_min,
            gain_max=params.gain_max,
        )
    rows = [
        {
            "phase": t.phase,
            "trial": t.index,
            "stimuli": " / ".join(t.stimuli),
            "slots": " ".join(t.slots),
            "start_gain": t.start_gain,
        }
        for t in plan.familiarisation + plan.test
    ]
    columns = [Column("phase", "phase", name=True), Column("trial", "trial"), Column("stimuli", "stimuli", name=True)]
    if args.protocol == "resynthesis":
        columns.append(Column("slots", "slots 1-5", name=True))
    if args.protocol == "intensity":
        columns.append(Column("start_gain", "start gain", _num(3)))
    emit(rows, columns, output_format(args))
    return 0


def run_analyze(args: argparse.Namespace) -> int:
    sessions = _open_sessions(args)
    protocol = sessions[0].protocol
    fmt = output_format(args)
    from vibsynth.research.lab.iso import is_sine_session

    if protocol == "intensity" and is_sine_session(sessions[0]):
        _iso(sessions, args, fmt)
    elif protocol == "intensity":
        _intensity(sessions, fmt)
    elif protocol == "dissimilarity":
        _dissimilarity(sessions, args, fmt)
    else:
        _resynthesis(sessions, fmt)
    return 0


def _who(sessions: list[Any]) -> str:
    done = sum(s.done for s in sessions)
    total = sum(s.total for s in sessions)
    people = ", ".join(s.participant for s in sessions)
    stimuli = sessions[0].meta["set"]["name"]
    return f"{len(sessions)} session(s) ({people}), {done}/{total} trials answered, stimuli {stimuli}"


def _agreement(result: Any, paper: str) -> None:
    print(
        f"agreement between participants: Pearson r = {result.participant_r:.2f} "
        f"(SD {result.participant_r_sd:.2f})   [paper: {paper}]"
    )


def _intensity(sessions: list[Any], fmt: str) -> None:
    from vibsynth.research.lab.analysis import analyze_intensity

    r = analyze_intensity(sessions)
    if fmt == "json":
        print(json.dumps(r.to_dict(), indent=2))
        return
    rows = [
        {
            "stimulus": sid,
            "level_db": r.level_db[k],
            "broadband_db": r.broadband_db[k],
            "gain": r.mean_gain[k],
            "judged_db": r.judged_db[k],
            "equalised_db": r.equalised_db[k],
        }
        for k, sid in enumerate(r.ids)
    ]
    columns = [
        Column("stimulus", "stimulus", name=True),
        Column("level_db", "80-200 Hz dB", _num(2)),
        Column("broadband_db", "10-1000 Hz dB", _num(2)),
        Column("gain", "mean gain", _num(3)),
        Column("judged_db", "judged dB", _num(2)),
        Column("equalised_db", "equalised dB", _num(2)),
    ]
    if fmt == "csv":
        emit(rows, [Column(c.key, c.key) for c in columns], "csv")
        return
    print(_who(sessions))
    emit(rows, columns, "table")
    print(
        f"intensity model: judged dB = {r.slope:.2f} x (80-200 Hz level) {r.intercept:+.2f}, R^2 = {r.r2:.3f}"
        f"   [paper: 0.90]; on the 10-1000 Hz level R^2 = {r.r2_broadband:.3f}   [paper: 0.07]"
    )
    print(f"80-200 Hz level SD: {r.level_sd_before:.2f} dB as played, {r.level_sd_after:.2f} dB after equalisation")
    if len(sessions) > 1:
        _agreement(r, "0.82, SD 0.08")


def _iso(sessions: list[Any], args: argparse.Namespace, fmt: str) -> None:
    from vibsynth.research.lab.iso import iso_curve

    response = None
    if args.profile:
        from vibsynth.settings.actuators import load_actuator_profile

        response = load_actuator_profile(args.profile)["response"]
    curve = iso_curve(sessions, response=response)
    if args.plot is not None:
        from vibsynth.research.plots import plot_iso_curve

        plot_iso_curve(curve, args.plot)
    if fmt == "json":
        print(json.dumps(curve.to_dict(), indent=2))
        return
    if fmt == "csv":
        sys.stdout.write(curve.to_csv())
        return
    print(_who(sessions))
    columns = [
        Column("frequency_hz", "Hz", _num(1)),
        Column("mean_db", "mean dB", _num(2)),
        Column("sd_db", "SD dB", _num(2)),
    ]
    if curve.acceleration_db is not None:
        columns.append(Column("acceleration_db", "accel. dB", _num(2)))
    columns += [Column(f"db_{who}", who, _num(2)) for who in curve.labels]
    emit(curve.rows(), columns, "table")
    print(
        f"iso-intensity curve: drive for the intensity of the {curve.reference_hz:g} Hz reference sine, dB re its drive"
    )
    if args.plot is not None:
        print(f"wrote {args.plot}")


def _dissimilarity(sessions: list[Any], args: argparse.Namespace, fmt: str) -> None:
    from vibsynth.cli.dissim import emit_weights_csv, print_fit
    from vibsynth.research.dissim import require_sklearn
    from vibsynth.research.lab.analysis import analyze_dissimilarity

    require_sklearn("vibsynth lab analyze")
    basis = basis_from_args(args)
    r = analyze_dissimilarity(sessions, basis=basis, n_splits=args.splits, seed=args.seed)
    if args.plot is not None and r.mds is not None:
        from vibsynth.research.plots import plot_mds

        plot_mds(r.mds, args.plot)
    if fmt == "json":
        print(json.dumps(r.to_dict(), indent=2))
        return
    if fmt == "csv":
        if r.fit is None:
            raise InputError(f"no fit to write: {r.problem}")
        emit_weights_csv(r.fit)
        return
    print(_who(sessions))
    print(
        f"{r.table.n_rows} ratings -> {len(r.table.pairs)} pairs; self-pairs rated {r.self_mean:.3f} "
        f"(SD {r.self_sd:.3f})   [paper: 0.12, SD 0.07]"
    )
    if len(sessions) > 1:
        _agreement(r, "0.51, SD 0.12")
    if r.fit is not None:
        print_fit(r.fit)
    if r.mds is not None:
        c = r.mds.component_r
        print(
            f"MDS map: t1 vs dimension 1 r = {c[0, 0]:+.2f}, vs dimension 2 r = {c[0, 1]:+.2f}   [paper: 0.94, -0.01]"
        )
        if args.plot is not None:
            print(f"wrote {args.plot}")
    if r.problem:
        print(f"note: {r.problem}")


def _resynthesis(sessions: list[Any], fmt: str) -> None:
    from vibsynth.research.lab.analysis import analyze_resynthesis

    r = analyze_resynthesis(sessions)
    if fmt == "json":
        print(json.dumps(r.to_dict(), indent=2))
        return
    columns = [
        Column("version", "version", name=True),
        Column("n", "n"),
        Column("mean", "mean", _num(3)),
        Column("sd", "SD", _num(3)),
        Column("median", "median", _num(3)),
    ]
    if fmt == "table":
        print(_who(sessions))
    emit(r.summary(), columns, fmt)


def run_equalise(args: argparse.Namespace) -> int:
    from vibsynth.research.lab.analysis import analyze_intensity, write_equalised_set

    sessions = _open_sessions(args)
    result = analyze_intensity(sessions)
    folder = write_equalised_set(result, sessions, args.output)
    print(f"wrote {folder}: {len(result.ids)} stimuli equalised by {len(sessions)} participant(s)")
    return 0
