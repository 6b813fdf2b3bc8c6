"""Follow offline, many files: one job per sound, run here, on the local cores, or on a Dask cluster.

A :class:`FollowJob` is plain data (paths, mode, focus, the typed settings, the basis), so it
pickles to a worker process or a Dask worker; :func:`run_job` does one file and never raises
for a bad file: it returns a :class:`JobOutcome` with one line of text, so a library of sounds
converts on even when some files are broken, and each failure is reported on its own line.
Writes are atomic (a clip through :func:`~vibsynth.settings.clips.save_clip`, a WAV through
:class:`~vibsynth.formats.wav_stream.WavStreamWriter`): a failed file leaves nothing behind.

Where the jobs run (:func:`run_jobs`):

* one job, or ``workers=1``: in this process (with the caller's progress callback);
* ``workers=N``: a process pool of N workers on this machine (each file on one core);
* ``dask=ADDRESS``: the scheduler of a running Dask cluster (``distributed``, the optional
  extra ``vibsynth[dask]``); its workers must see the input and output paths (a shared file
  system) and have vibsynth installed.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from vibsynth.dsp.basis import Basis
from vibsynth.errors import ClipError, InputError, MissingDependencyError, ParameterError, VibsynthError
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["FollowJob", "JobOutcome", "run_job", "run_jobs", "default_workers", "connect_dask", "sound_files"]

Kind = Literal["clip", "render"]
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class FollowJob:
    """One sound to convert.

    Attributes
    ----------
    kind : {"clip", "render"}
        A clip file (``clip from-audio``) or a haptic track WAV (``render --follow``).
    source, target : str
        Input WAV and the file to write.
    settings : VibsynthConfig
    mode, focus : str
    basis : Basis or None
        None: the shipped basis.
    name : str
        Clip name (kind "clip"); must match the target's stem.
    options : dict
        Clip: ``tolerance_db``, ``tolerance_balance``, ``max_keyframes``; render: ``sample_format``,
        ``make_folder`` (create the target's folder).
    force : bool
        Replace an existing target.
    """

    kind: Kind
    source: str
    target: str
    settings: VibsynthConfig
    mode: str = "vibration"
    focus: str = "all"
    basis: Basis | None = None
    name: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    force: bool = False


@dataclass(frozen=True)
class JobOutcome:
    """What one job did: ``ok`` and one line (a summary, or the error)."""

    source: str
    target: str
    ok: bool
    message: str
    seconds: float = 0.0


def _stream(job: FollowJob) -> Any:
    from vibsynth.app.follow_offline import FollowStream

    return FollowStream(job.source, settings=job.settings, mode=job.mode, focus=job.focus, basis=job.basis)


def _clip(job: FollowJob, progress: Progress | None) -> str:
    from vibsynth.app.follow_offline import clip_from_audio
    from vibsynth.settings.clips import save_clip

    made = clip_from_audio(_stream(job), name=job.name, settings=job.settings, progress=progress, **job.options)
    result = made.clip
    header = f"# vibsynth clip made by clip from-audio from {job.source}: {made.summary()}\n"
    save_clip(result, job.target, header=header)
    return made.summary() + ("; the input is silent: the clip is silence" if made.silent else "")


def _render(job: FollowJob, progress: Progress | None) -> str:
    from vibsynth.app.follow_offline import prepare_follow_render
    from vibsynth.app.render import render
    from vibsynth.formats.wav_stream import WavStreamWriter

    fmt = job.options.get("sample_format", "float32")
    render_job = prepare_follow_render(_stream(job), settings=job.settings, basis=job.basis)
    with render_job.stream:
        engine, frames = render_job.engine, render_job.frames
        with WavStreamWriter(
            job.target,
            render_job.fs,
            engine.channels,
            sample_format=fmt,
            frames=frames,
            make_folder=bool(job.options.get("make_folder")),
        ) as wav:
            result = render(engine, frames, wav, timeline=render_job.timeline, progress=progress)
        silent = render_job.stream.silent
    db = 20 * math.log10(result.peak) if result.peak > 0 else -math.inf
    line = f"{result.seconds:.2f} s at {result.fs:g} Hz, peak {db:.1f} dBFS"
    return line + ("; the input is silent: the track is silence" if silent else "")


def run_job(job: FollowJob, progress: Progress | None = None) -> JobOutcome:
    """Do one job; a bad file is an outcome (``ok`` False, one line), never an exception.

    ``KeyboardInterrupt`` still propagates.
    """
    started = time.perf_counter()
    try:
        target = Path(job.target)
        if target.exists() and not job.force:
            raise ClipError(f"{target}: exists already (use --force to replace it)")
        message = (_clip if job.kind == "clip" else _render)(job, progress)
        ok = True
    except VibsynthError as exc:
        message, ok = str(exc), False
    except OSError as exc:
        where = exc.filename if exc.filename is not None else job.target
        message, ok = f"{where}: {exc.strerror or exc}", False
    except MemoryError:
        message, ok = f"{job.source}: out of memory", False
    except Exception as exc:  # a bug: reported for this file, the others go on
        message, ok = f"{job.source}: unexpected {type(exc).__name__}: {exc} (a bug: please report it)", False
    message = " ".join(message.split())  # one line, whatever an exception said
    return JobOutcome(job.source, job.target, ok, message, time.perf_counter() - started)


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def connect_dask(address: str) -> Any:
    """A ``distributed.Client`` of the cluster at ``address`` (``tcp://host:8786``).

    Raises
    ------
    MissingDependencyError
        ``distributed`` is not installed.
    InputError
        The scheduler cannot be reached (one line).
    """
    try:
        from distributed import Client
    except ImportError:
        raise MissingDependencyError("--dask needs the distributed package: pip install 'vibsynth[dask]'") from None
    try:
        return Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        text = " ".join(str(exc).split())
        raise InputError(f"cannot reach the Dask scheduler at {address} ({text})") from None


def run_jobs(
    jobs: Sequence[FollowJob],
    *,
    workers: int = 1,
    dask: str | None = None,
    on_outcome: Callable[[JobOutcome], None] | None = None,
    progress: Progress | None = None,
) -> list[JobOutcome]:
    """Run jobs and report each outcome as it completes.

    Parameters
    ----------
    jobs : sequence of FollowJob
    workers : int
        Local processes (1: here, in order).
    dask : str, optional
        A Dask scheduler address: run there instead (``workers`` is ignored).
    on_outcome : callable, optional
        Called with each :class:`JobOutcome` as it completes (in completion order).
    progress : callable, optional
        For a single job run here: the job's own ``progress(done, total)`` (input or output frames).

    Returns
    -------
    outcomes : list of JobOutcome
        In the order of ``jobs``.
    """
    if workers < 1:
        raise ParameterError(f"workers must be at least 1, got {workers}")
    outcomes: dict[int, JobOutcome] = {}

    def done(i: int, outcome: JobOutcome) -> None:
        outcomes[i] = outcome
        if on_outcome is not None:
            on_outcome(outcome)

    if dask is not None:
        try:
            _run_dask(jobs, dask, done)
        except (OSError, TimeoutError, ValueError, RuntimeError) as exc:  # the cluster went away mid-run
            text = " ".join(str(exc).split())
            raise InputError(f"the Dask cluster at {dask} failed ({type(exc).__name__}: {text})") from None
    elif workers == 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            done(i, run_job(job, progress if len(jobs) == 1 else None))
    else:
        import multiprocessing

        context = multiprocessing.get_context("spawn")  # no inherited threads or locks from this process
        with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=context) as pool:
            futures = {pool.submit(run_job, job): i for i, job in enumerate(jobs)}
            for future in as_completed(futures):
                i = futures[future]
                done(i, _result(future, jobs[i]))
    return [outcomes[i] for i in range(len(jobs))]


def _result(future: Any, job: FollowJob) -> JobOutcome:
    """A future's outcome; a worker that died is this file's failure."""
    try:
        outcome: JobOutcome = future.result()
    except Exception as exc:  # the worker process died (killed, out of memory) or the cluster lost it
        return JobOutcome(
            job.source, job.target, False, f"{job.source}: the worker failed ({type(exc).__name__}: {exc})"
        )
    return outcome


def _run_dask(jobs: Sequence[FollowJob], address: str, done: Callable[[int, JobOutcome], None]) -> None:
    from distributed import as_completed as dask_completed

    client = connect_dask(address)
    try:
        futures = client.map(run_job, list(jobs), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for future in dask_completed(futures, loop=client.loop):
            i = index[future.key]
            done(i, _result(future, jobs[i]))
    finally:
        client.close()


def sound_files(folder: Path) -> Iterable[Path]:
    """The sound files under a folder (by name: :data:`~vibsynth.formats.sound_reader.SOUND_SUFFIXES`), sorted
    (sub-folders walked)."""
    from vibsynth.formats.sound_reader import SOUND_SUFFIXES

    for path in sorted(folder.rglob("*")):
        if path.is_file() and path.suffix.lower() in SOUND_SUFFIXES:
            yield path
