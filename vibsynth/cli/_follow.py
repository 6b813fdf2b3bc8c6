"""Follow offline on the command line: ``clip from-audio`` and ``render --follow``, one file or a folder.

Both commands take a sound file (WAV, FLAC, Ogg, MP3...: :mod:`vibsynth.formats.sound_reader`) or a
folder of them. One file runs here with a progress bar; a
folder runs ``--jobs`` files at a time on the local cores (default: all of them), or on a Dask
cluster with ``--dask ADDRESS``. Each file's result is one line (``wrote ...`` on stdout, or
``vibsynth: error: ...`` on stderr) and the rest of the folder goes on; the exit code is 1 when
any file failed.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path
from typing import Any

from vibsynth.app.follow_batch import FollowJob, JobOutcome, default_workers, run_jobs, sound_files
from vibsynth.cli._common import basis_from_args, integer_in, number_in
from vibsynth.cli._inputs import MAX_FILES
from vibsynth.cli._progress import RenderProgress, add_quiet_argument
from vibsynth.dsp.follow.params import FOCUSES, MODES
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.sound_reader import READABLE
from vibsynth.settings.models_clip import MAX_KEYFRAMES
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["add_follow_options", "add_from_audio_parser", "run_follow_render", "run_from_audio"]


def add_follow_options(parser: argparse.ArgumentParser, *, prefix: str = "", force: bool = True) -> None:
    """``--[prefix]mode``, ``--[prefix]focus``, ``--jobs``, ``--dask`` (and ``--force``)."""
    parser.add_argument(
        f"--{prefix}mode",
        choices=MODES,
        default="vibration",
        help="vibration: the input is a vibration (the paper's model); audio: program audio (docs/follow.md)",
    )
    parser.add_argument(
        f"--{prefix}focus", choices=FOCUSES, default="all", help="audio mode: what shakes (default all)"
    )
    parser.add_argument(
        "--jobs",
        type=integer_in(1, 1024, what="jobs"),
        default=None,
        metavar="N",
        help="files converted at a time from a folder (default: every core)",
    )
    parser.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="convert a folder on this Dask cluster (tcp://host:8786; pip install 'vibsynth[dask]')",
    )
    if force:
        parser.add_argument("--force", action="store_true", help="replace existing output files")


def add_from_audio_parser(sub: Any, add_config_arguments: Any) -> None:
    """``vibsynth clip from-audio IN.wav|FOLDER -o NAME|FILE.yaml|FOLDER``."""
    p = sub.add_parser(
        "from-audio",
        help="make a clip from a sound or vibration recording (the Follow tracker, offline)",
        description="Track a sound file (WAV, FLAC, Ogg, MP3, AIFF...; any channels, mixed; any rate) as Follow "
        "does live and write a clip: "
        "keyframes of intensity and balance, simplified to at most --max-keyframes within the tolerances "
        "(the error reached is printed and kept in the clip), and onsets as transients, aligned to the input. "
        "A folder converts every sound file under it into -o FOLDER, in parallel (docs/clips.md, docs/follow.md).",
    )
    add_config_arguments(p)
    p.add_argument("input", type=Path, metavar="IN.wav|FOLDER")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="NAME|FILE.yaml|FOLDER",
        help="a clip name (the user clip folder), a clip file, or a folder (required for a folder of sounds)",
    )
    add_follow_options(p)
    p.add_argument(
        "--tolerance-db",
        type=number_in(0.0, 40.0, unit="dB", low_open=True),
        default=1.0,
        metavar="DB",
        help="largest intensity error of the simplified curve, dB (default 1)",
    )
    p.add_argument(
        "--tolerance-balance",
        type=number_in(0.0, 5.0, low_open=True),
        default=0.1,
        metavar="B",
        help="largest balance error, knob units (default 0.1)",
    )
    p.add_argument(
        "--max-keyframes",
        type=integer_in(2, MAX_KEYFRAMES, what="max keyframes"),
        default=MAX_KEYFRAMES,
        metavar="N",
        help=f"at most this many keyframes (default {MAX_KEYFRAMES}, the most a clip holds)",
    )
    add_quiet_argument(p)
    p.add_argument("--basis", metavar="FILE.yaml", type=Path, help="spectral basis (default: the shipped one)")
    p.set_defaults(func=run_from_audio)


# --------------------------------------------------------------------------- planning
def _inputs(path: Path) -> list[Path]:
    if path.is_dir():
        found = []
        for f in sound_files(path):
            found.append(f)
            if len(found) > MAX_FILES:
                raise InputError(f"{path}: more than {MAX_FILES:,} sound files; name a smaller folder")
        if not found:
            raise InputError(f"{path}: no sound files in this folder ({READABLE})")
        return found
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    return [path]


def _clip_name(stem: str) -> str:
    from vibsynth.settings.clip_convert import clip_name

    return clip_name(stem)


def _clip_target(output: str, source: Path, settings: VibsynthConfig) -> tuple[Path, str]:
    """Where a single clip goes: a file (``.yaml``), into a folder, or a name in the user clip folder."""
    out = Path(output)
    if output.endswith(".yaml"):
        return out, _clip_name(out.stem)
    if out.is_dir() or "/" in output or output.endswith(("\\", ".")):
        name = _clip_name(source.stem)
        return out / f"{name}.yaml", name
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}", output):
        raise ParameterError(f"-o {output!r}: not a clip name, a FILE.yaml or a folder")
    from vibsynth.settings.clips import load_clip_library

    folder = load_clip_library(settings).user_dir
    if folder is None:
        raise ParameterError("no user clip folder is configured (clips.user_dir); give -o FILE.yaml")
    return folder / f"{output}.yaml", output


def _folder_targets(sources: list[Path], root: Path, out: Path, suffix: str) -> list[tuple[Path, str]]:
    if out.exists() and not out.is_dir():
        raise ParameterError(f"-o {out}: a folder of sounds needs an output folder, not a file")
    targets = []
    for s in sources:
        rel = s.relative_to(root)
        name = _clip_name(s.stem)
        stem = name if suffix == ".yaml" else s.stem
        targets.append((out / rel.parent / f"{stem}{suffix}", name))
    return targets


def _plan(args: argparse.Namespace, kind: str, settings: VibsynthConfig, options: dict[str, Any]) -> list[FollowJob]:
    source: Path = args.input if kind == "clip" else Path(args.follow)
    sources = _inputs(source)
    output = str(args.output)
    if source.is_dir():
        targets = _folder_targets(sources, source, Path(output), ".yaml" if kind == "clip" else ".wav")
    elif kind == "clip":
        targets = [_clip_target(output, source, settings)]
    else:
        targets = [(Path(output), "")]
    mode = args.mode if kind == "clip" else args.follow_mode
    focus = args.focus if kind == "clip" else args.follow_focus
    basis = basis_from_args(args) if getattr(args, "basis", None) else None
    return [
        FollowJob(
            kind,  # type: ignore[arg-type]
            str(src),
            str(target),
            settings,
            mode=mode,
            focus=focus,
            basis=basis,
            name=name,
            options=options,
            force=getattr(args, "force", True),  # render replaces its output, as every render does
        )
        for src, (target, name) in zip(sources, targets)
    ]


# --------------------------------------------------------------------------- running
def _execute(args: argparse.Namespace, jobs: list[FollowJob], label: str) -> int:
    """Run the jobs, one line per file; exit code 1 when any failed."""
    started = time.perf_counter()
    quiet = bool(getattr(args, "quiet", False))

    def report(outcome: JobOutcome) -> None:
        if outcome.ok:
            if not quiet:
                print(f"wrote {outcome.target}: {outcome.message}", flush=True)
        else:
            print(f"vibsynth: error: {outcome.message}", file=sys.stderr, flush=True)

    workers = args.jobs or default_workers()
    if len(jobs) == 1 and args.dask is None:
        from vibsynth.formats.sound_reader import open_sound

        with open_sound(jobs[0].source) as r:  # the bar counts seconds of input
            frames, fs = r.frames, r.fs
        with RenderProgress(label, frames, fs, quiet=quiet) as bar:
            outcomes = run_jobs(jobs, workers=1, on_outcome=report, progress=bar)
    else:
        with RenderProgress(label, len(jobs), 1.0, quiet=quiet, unit="files") as bar:
            count = [0]

            def step(outcome: JobOutcome) -> None:
                count[0] += 1
                bar(count[0], len(jobs))
                report(outcome)

            outcomes = run_jobs(jobs, workers=workers, dask=args.dask, on_outcome=step)
    failed = sum(1 for o in outcomes if not o.ok)
    if len(jobs) > 1 and not quiet:
        where = f"on {args.dask}" if args.dask else f"{min(workers, len(jobs))} at a time"
        print(
            f"{len(jobs) - failed} of {len(jobs)} files converted ({failed} failed), {where}, "
            f"in {time.perf_counter() - started:.1f} s"
        )
    return 1 if failed else 0


def _settings(args: argparse.Namespace) -> VibsynthConfig:
    from vibsynth.settings.config import settings_from_args

    return settings_from_args(args)


def run_from_audio(args: argparse.Namespace) -> int:
    """``clip from-audio``: exit 0, or 1 when a file failed; bad arguments raise (exit 2)."""
    options = {
        "tolerance_db": args.tolerance_db,
        "tolerance_balance": args.tolerance_balance,
        "max_keyframes": args.max_keyframes,
    }
    try:
        jobs = _plan(args, "clip", _settings(args), options)
    except InputError as exc:
        print(f"vibsynth: error: {exc}", file=sys.stderr)
        return 1
    return _execute(args, jobs, "follow")


def run_follow_render(args: argparse.Namespace, settings: VibsynthConfig) -> int:
    """``render --follow``: exit 0, or 1 when a file failed."""
    try:
        options = {"sample_format": args.format, "make_folder": Path(args.follow).is_dir()}
        jobs = _plan(args, "render", settings, options)
    except InputError as exc:
        print(f"vibsynth: error: {exc}", file=sys.stderr)
        return 1
    return _execute(args, jobs, "render")
