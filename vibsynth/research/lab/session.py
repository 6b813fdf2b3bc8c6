"""Session folders: created exclusively, never overwritten, resumed from the CSV written so far.

A session folder holds

* ``session.json``: written once, atomically, when the session is created: protocol,
  participant, seed, parameters, the stimulus set, every stimulus' id and parameters, and the
  whole plan (so a resume does not depend on rebuilding it);
* ``stimuli/<id>.wav``: every stimulus exactly as it is played (float32, its own rate);
* ``trials.csv``: one row per data trial (:mod:`~vibsynth.research.lab.records`), appended
  and fsynced as each trial is answered. A ``kill -9`` loses at most the trial in progress;
  a row cut short by it is dropped when the session is resumed.

A folder is created with ``mkdir`` (which fails when it exists) and the CSV with ``O_EXCL``,
so nothing is ever written over. While a session is open for writing its CSV is locked
(``flock``), so two runners cannot append to one session.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vibsynth._version import __version__
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.files import atomic_write_text, fsync_folder, read_text
from vibsynth.formats.recordings import read_recording, write_wav
from vibsynth.research.lab.orders import Plan, Trial
from vibsynth.research.lab.protocol import (
    LabParameters,
    Protocol,
    check_participant,
    check_protocol,
    check_seed,
)
from vibsynth.research.lab.records import Answer, check_row, columns, make_row, parse_timestamp, timestamp
from vibsynth.research.lab.staircase import METHODS, Track, check_method, rule_of, track
from vibsynth.research.lab.stimuli import Stimulus

if TYPE_CHECKING:
    from vibsynth.settings.models_lab import Lab

__all__ = [
    "SESSION_FILE",
    "TRIALS_FILE",
    "STIMULI_DIR",
    "SESSION_FORMAT",
    "SessionInfo",
    "Session",
    "default_root",
    "sessions_root",
    "list_sessions",
    "json_ready",
]

SESSION_FILE = "session.json"
TRIALS_FILE = "trials.csv"
STIMULI_DIR = "stimuli"
SESSION_FORMAT = "vibsynth-lab-session"
SESSION_VERSION = 1
#: session.json of 60 stimuli with the 1,830-pair plan is about 300 KB.
MAX_SESSION_BYTES = 16 << 20
#: trials.csv of the longest plan is under 1 MB.
MAX_TRIALS_BYTES = 64 << 20
#: Entries of the sessions folder looked at by :func:`list_sessions`.
MAX_LISTED = 10_000


def default_root() -> Path:
    """The platform folder for sessions: ``lab/`` in the user data folder
    (Linux ``~/.local/share/vibsynth/lab``)."""
    import platformdirs

    return Path(platformdirs.user_data_dir("vibsynth", appauthor=False)) / "lab"


def sessions_root(lab: Lab | None = None) -> Path:
    """Where sessions go: ``lab.folder`` of the typed ``lab:`` section, else :func:`default_root`."""
    folder = lab.folder if lab is not None else None
    return Path(folder).expanduser() if folder else default_root()


@dataclass(frozen=True)
class SessionInfo:
    """What a listing shows of a session.

    Attributes
    ----------
    folder : pathlib.Path
    protocol, participant : str
    seed : int
    created : str
        ISO timestamp (UTC).
    set_name : str
        The stimulus set.
    set_kind : str
        ``folder``, ``presets`` or ``renders``.
    done, total : int
        Data trials answered, and planned.
    """

    folder: Path
    protocol: str
    participant: str
    seed: int
    created: str
    set_name: str
    set_kind: str
    done: int
    total: int

    @property
    def complete(self) -> bool:
        """Every data trial is answered."""
        return self.done >= self.total

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON output, the studio's list)."""
        return {
            "folder": str(self.folder),
            "protocol": self.protocol,
            "participant": self.participant,
            "seed": self.seed,
            "created": self.created,
            "set": self.set_name,
            "set_kind": self.set_kind,
            "done": self.done,
            "total": self.total,
            "complete": self.complete,
        }


def _lock(fd: int, path: Path) -> None:
    try:
        import fcntl
    except ImportError:  # Windows: no advisory lock; one runner per session is then the user's care
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        raise InputError(f"{path}: the session is open in another runner") from None


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        written = os.write(fd, view)
        view = view[written:]


def _csv_line(values: Sequence[str]) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerow(values)
    return buffer.getvalue()


def _session_name(participant: str, protocol: str, now: datetime) -> str:
    return f"{participant}-{protocol}-{now.astimezone().strftime('%Y%m%d-%H%M%S')}"


def _claim_folder(root: Path, name: str) -> Path:
    """mkdir a fresh folder ``name`` (``name-2``, ``name-3``... when taken): never an existing one."""
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{root}: cannot create the sessions folder ({exc.strerror or exc})") from None
    for k in range(1, 100):
        folder = root / (name if k == 1 else f"{name}-{k}")
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise InputError(f"{folder}: cannot create ({exc.strerror or exc})") from None
        return folder
    raise InputError(f"{root}: 99 sessions named {name}-*; pick another participant id")


class Session:
    """A session folder, open for reading or for appending trials.

    Use :meth:`create` or :meth:`open`; :meth:`close` (or ``with``) releases the CSV.

    Attributes
    ----------
    folder : pathlib.Path
    meta : dict
        session.json.
    plan : Plan
    rows : list of dict
        The data trials answered so far (the CSV's rows).
    """

    def __init__(self, folder: Path, meta: dict[str, Any], plan: Plan, rows: list[dict[str, str]], fd: int | None):
        self.folder = folder
        self.meta = meta
        self.plan = plan
        self.rows = rows
        self._fd = fd
        self._stimuli: dict[str, Stimulus] | None = None

    # ------------------------------------------------------------------ properties
    @property
    def protocol(self) -> Protocol:
        """The session's protocol."""
        return check_protocol(self.meta["protocol"])

    @property
    def participant(self) -> str:
        """The participant's id."""
        return str(self.meta["participant"])

    @property
    def seed(self) -> int:
        """The seed of the plan."""
        return int(self.meta["seed"])

    @property
    def parameters(self) -> LabParameters:
        """The parameters the session runs with."""
        return LabParameters(**self.meta["parameters"])

    @property
    def method(self) -> str:
        """``adjustment`` (the slider), or ``staircase``/``staircase-2d1u`` (intensity on sines)."""
        return str(self.meta.get("method") or "adjustment")

    def track(self, stimulus: str) -> Track:
        """A staircase session: the staircase of one stimulus after the answers so far.

        Its start is the gain the plan gives that stimulus' first trial; levels are dB of gain.
        """
        start = next(t.start_gain for t in self.plan.test if t.stimuli[0] == stimulus and t.start_gain)
        answers = [r["judgement"] == "stronger" for r in self.rows if r["stimulus"] == stimulus]
        p = self.parameters
        return track(
            20.0 * math.log10(start),
            answers,
            rule=rule_of(self.method),
            low_db=20.0 * math.log10(p.gain_min),
            high_db=20.0 * math.log10(p.gain_max),
        )

    def staircase_gain(self) -> float:
        """A staircase session: the gain the next trial's test sine plays at."""
        trial = self.next_trial
        if trial is None:
            raise InputError(f"{self.folder}: the session is complete ({self.total} trials)")
        return float(10.0 ** (self.track(trial.stimuli[0]).next_db / 20.0))

    @property
    def done(self) -> int:
        """Data trials answered."""
        return len(self.rows)

    @property
    def total(self) -> int:
        """Data trials planned."""
        return len(self.plan.test)

    @property
    def complete(self) -> bool:
        """Every data trial is answered."""
        return self.done >= self.total

    @property
    def next_trial(self) -> Trial | None:
        """The next data trial, or None when the session is complete."""
        return None if self.complete else self.plan.test[self.done]

    @property
    def trials_path(self) -> Path:
        """The CSV."""
        return self.folder / TRIALS_FILE

    def params(self) -> dict[str, dict[str, Any]]:
        """Each stimulus' parameters, by id."""
        return {sid: dict(entry["params"]) for sid, entry in self.meta["stimuli"].items()}

    def info(self) -> SessionInfo:
        """What a listing shows."""
        return SessionInfo(
            folder=self.folder,
            protocol=self.protocol,
            participant=self.participant,
            seed=self.seed,
            created=str(self.meta["created"]),
            set_name=str(self.meta["set"]["name"]),
            set_kind=str(self.meta["set"].get("kind", "")),
            done=self.done,
            total=self.total,
        )

    def stimuli(self) -> dict[str, Stimulus]:
        """Every stimulus of the session (the reference and the resynthesis versions included), by id,
        read from its WAV as it is played."""
        if self._stimuli is None:
            out = {}
            for sid, entry in self.meta["stimuli"].items():
                rec = read_recording(self.folder / entry["file"])
                out[sid] = Stimulus(sid, rec.samples, rec.fs, dict(entry["params"]))
            self._stimuli = out
        return self._stimuli

    # ------------------------------------------------------------------ creating
    @classmethod
    def create(
        cls,
        root: str | os.PathLike[str],
        *,
        protocol: str,
        participant: str,
        seed: int,
        stimuli: Sequence[Stimulus],
        plan: Plan,
        parameters: LabParameters,
        set_info: Mapping[str, Any],
        basis_id: str,
        reference: str | None = None,
        originals: Sequence[str] | None = None,
        folder: str | os.PathLike[str] | None = None,
        now: datetime | None = None,
        method: str = "adjustment",
    ) -> Session:
        """Create a session folder (never an existing one) and open it for appending trials.

        Parameters
        ----------
        root : path-like
            The sessions folder; the session gets ``<participant>-<protocol>-<date>-<time>``
            (``-2``... if taken).
        protocol, participant, seed
            Checked (:func:`check_participant` refuses path characters).
        stimuli : sequence of Stimulus
            Every stimulus the plan plays (prepared), the reference and the versions included.
        plan : Plan
        parameters : LabParameters
        set_info : mapping
            ``name``, ``kind``, ``equalised``, ``normalise`` of the stimulus set.
        basis_id : str
            The basis the parameters were measured on.
        reference : str, optional
            The intensity reference's id.
        originals : sequence of str, optional
            The stimuli of the set proper (resynthesis: the originals).
        folder : path-like, optional
            An explicit session folder instead of a name under ``root``; refused if it exists.
        now : datetime, optional
            Creation time (tests).
        method : str
            Intensity: ``adjustment`` or a staircase (:mod:`~vibsynth.research.lab.staircase`).

        Raises
        ------
        InputError
            The folder exists or cannot be written; a stimulus the plan needs is missing.
        ParameterError
            A bad protocol, participant id or seed.
        """
        name = check_protocol(protocol)
        who = check_participant(participant)
        seed = check_seed(seed)
        by_id = {s.id: s for s in stimuli}
        if len(by_id) != len(stimuli):
            raise ParameterError("stimulus ids must be unique")
        needed = {sid for t in plan.familiarisation + plan.test for sid in t.stimuli}
        missing = sorted(needed - set(by_id))
        if missing:
            raise ParameterError(f"the plan plays stimuli that are not in the set: {', '.join(missing[:5])}")
        now = now or datetime.now(timezone.utc)
        if folder is not None:
            target = Path(folder).expanduser()
            try:
                target.mkdir(parents=False)
            except FileExistsError:
                raise InputError(
                    f"{target}: already exists; a session folder is never overwritten (resume it, or pick a new one)"
                ) from None
            except OSError as exc:
                raise InputError(f"{target}: cannot create ({exc.strerror or exc})") from None
        else:
            target = _claim_folder(Path(root).expanduser(), _session_name(who, name, now))
        fd: int | None = None
        try:
            (target / STIMULI_DIR).mkdir()
            entries: dict[str, Any] = {}
            for s in stimuli:
                rel = f"{STIMULI_DIR}/{s.id}.wav"
                write_wav(target / rel, s.samples, s.fs)
                entries[s.id] = {"file": rel, "params": json_ready(dict(s.params))}
            meta = {
                "format": SESSION_FORMAT,
                "version": SESSION_VERSION,
                "protocol": name,
                "participant": who,
                "seed": seed,
                "created": timestamp(now),
                "vibsynth": __version__,
                "basis": basis_id,
                "parameters": parameters.to_dict(),
                "set": json_ready(dict(set_info)),
                "reference": reference,
                "originals": list(originals) if originals is not None else None,
                "stimuli": entries,
                "plan": plan.to_dict(),
                "method": check_method(method),
            }
            atomic_write_text(target / SESSION_FILE, json.dumps(meta, indent=1, allow_nan=False) + "\n")
            flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_APPEND | getattr(os, "O_CLOEXEC", 0)
            fd = os.open(target / TRIALS_FILE, flags, 0o666)
            _lock(fd, target / TRIALS_FILE)
            _write_all(fd, _csv_line(columns(name, method)).encode("utf-8"))
            os.fsync(fd)
            fsync_folder(target)
        except BaseException as exc:
            if fd is not None:
                os.close(fd)
            shutil.rmtree(target, ignore_errors=True)  # the folder this call created, nothing else
            if isinstance(exc, OSError):
                raise InputError(f"{target}: cannot write the session ({exc.strerror or exc})") from None
            raise
        return cls(target, meta, plan, [], fd)

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, folder: str | os.PathLike[str], *, write: bool = False) -> Session:
        """Open a session folder.

        Parameters
        ----------
        folder : path-like
        write : bool
            Open for appending trials (resume): the CSV is locked, and a last row cut short by
            a crash is removed so the next trial starts on a line of its own.

        Raises
        ------
        InputError
            Not a session folder; session.json or trials.csv unreadable, corrupt, or not
            matching the plan (the message names file and line); the session is open in
            another runner.
        """
        path = Path(folder).expanduser()
        meta = _read_meta(path)
        plan = _plan_from_meta(meta, path)
        csv_path = path / TRIALS_FILE
        fd: int | None = None
        try:
            if write:
                fd = os.open(csv_path, os.O_RDWR | os.O_APPEND | getattr(os, "O_CLOEXEC", 0))
                _lock(fd, csv_path)
                size = os.fstat(fd).st_size
                if size > MAX_TRIALS_BYTES:
                    raise InputError(f"{csv_path}: {size:,} bytes, more than any plan writes; not read")
                data = os.pread(fd, size, 0) if hasattr(os, "pread") else csv_path.read_bytes()
                complete = data[: data.rfind(b"\n") + 1]
                if len(complete) != len(data):  # a row cut short by a crash: the trial in progress
                    os.ftruncate(fd, len(complete))
                    os.fsync(fd)
                    data = complete
            else:
                with open(csv_path, "rb") as handle:
                    data = handle.read(MAX_TRIALS_BYTES + 1)
                if len(data) > MAX_TRIALS_BYTES:
                    raise InputError(f"{csv_path}: larger than any plan writes; not read")
                data = data[: data.rfind(b"\n") + 1]
            rows = _read_rows(data, csv_path, meta["protocol"], plan, str(meta.get("method") or "adjustment"))
        except FileNotFoundError:
            raise InputError(f"{csv_path}: missing; not a complete session folder") from None
        except OSError as exc:
            if fd is not None:
                os.close(fd)
            raise InputError(f"{csv_path}: cannot read ({exc.strerror or exc})") from None
        except BaseException:
            if fd is not None:
                os.close(fd)
            raise
        return cls(path, meta, plan, rows, fd)

    # ------------------------------------------------------------------ recording
    def record(self, answer: Answer, *, shown_at: datetime, answered_at: datetime) -> dict[str, str]:
        """Append the next data trial's row and fsync it.

        Parameters
        ----------
        answer : Answer
        shown_at, answered_at : datetime

        Returns
        -------
        row : dict of str to str

        Raises
        ------
        ParameterError
            The answer is out of range (nothing is written).
        InputError
            The session is complete, not open for writing, or the disk refuses the row.
        """
        if self._fd is None:
            raise InputError(f"{self.folder}: the session is not open for writing")
        trial = self.next_trial
        if trial is None:
            raise InputError(f"{self.folder}: the session is complete ({self.total} trials)")
        params = self.meta["parameters"]
        if self.method != "adjustment":  # the staircase, not the participant, sets the gain
            answer = replace(answer, value=self.staircase_gain())
        row = make_row(
            self.protocol,
            trial,
            answer,
            params=self.params(),
            shown_at=shown_at,
            answered_at=answered_at,
            participant=self.participant,
            gain_range=(float(params["gain_min"]), float(params["gain_max"])),
            reference=str(self.meta.get("reference") or ""),
            method=self.method,
        )
        try:
            _write_all(self._fd, _csv_line(list(row.values())).encode("utf-8"))
            os.fsync(self._fd)
        except OSError as exc:
            raise InputError(f"{self.trials_path}: cannot append the trial ({exc.strerror or exc})") from None
        self.rows.append(row)
        return row

    def close(self) -> None:
        """Release the CSV (and its lock)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def json_ready(value: Any) -> Any:
    """JSON-ready data: numpy arrays and numbers to Python lists and numbers, NaN and infinities to None."""
    import math

    import numpy as np

    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _read_meta(folder: Path) -> dict[str, Any]:
    path = folder / SESSION_FILE
    if not folder.is_dir():
        raise InputError(f"{folder}: no such session folder")
    if not path.is_file():
        raise InputError(f"{folder}: not a lab session folder (no {SESSION_FILE})")
    text = read_text(path, max_bytes=MAX_SESSION_BYTES, what="a session file")
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}:{exc.lineno}: not valid JSON ({exc.msg})") from None
    if not isinstance(meta, dict) or meta.get("format") != SESSION_FORMAT:
        raise InputError(f"{path}: not a vibsynth lab session (format {SESSION_FORMAT!r} expected)")
    if meta.get("version") != SESSION_VERSION:
        raise InputError(f"{path}: session version {meta.get('version')!r}; this vibsynth reads {SESSION_VERSION}")
    try:
        check_protocol(meta["protocol"])
        check_participant(meta["participant"])
        check_seed(meta["seed"])
        if meta.get("method", "adjustment") not in METHODS:
            raise ValueError(f"unknown method {str(meta.get('method'))[:40]!r}")
        LabParameters(**meta["parameters"])
        stimuli = meta["stimuli"]
        if not isinstance(stimuli, dict) or not all(
            isinstance(e, dict) and isinstance(e.get("params"), dict) and e.get("file") == f"{STIMULI_DIR}/{sid}.wav"
            for sid, e in stimuli.items()
        ):
            raise ValueError("stimuli must map each id to its file stimuli/<id>.wav and its params")
        if not isinstance(meta["set"], dict) or "name" not in meta["set"]:
            raise ValueError("set must name the stimulus set")
        parse_timestamp(meta["created"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: not a valid session ({type(exc).__name__}: {exc})") from None
    return meta


def _plan_from_meta(meta: dict[str, Any], folder: Path) -> Plan:
    try:
        plan = meta["plan"]
        fam = tuple(Trial.from_dict(t, "familiarisation") for t in plan["familiarisation"])
        test = tuple(Trial.from_dict(t, "test") for t in plan["test"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{folder / SESSION_FILE}: the plan is not valid ({exc})") from None
    known = set(meta["stimuli"])
    for t in fam + test:
        if not set(t.stimuli) <= known:
            raise InputError(f"{folder / SESSION_FILE}: trial {t.index} plays a stimulus that is not in the session")
    if not test:
        raise InputError(f"{folder / SESSION_FILE}: the plan has no trials")
    return Plan(check_protocol(meta["protocol"]), int(meta["seed"]), fam, test)


def _read_rows(data: bytes, path: Path, protocol: Protocol, plan: Plan, method: str) -> list[dict[str, str]]:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    reader = csv.reader(io.StringIO(text))
    header = tuple(next(reader, ()))
    if header != columns(protocol, method):
        raise InputError(
            f"{path}:1: the header is not the {protocol} protocol's ({', '.join(columns(protocol)[:4])}...)"
        )
    rows: list[dict[str, str]] = []
    try:
        for line, values in enumerate(reader, start=2):
            if len(values) != len(header):
                raise InputError(f"{path}:{line}: {len(values)} fields, the header has {len(header)}")
            if len(rows) >= len(plan.test):
                raise InputError(f"{path}:{line}: more rows than the plan's {len(plan.test)} trials")
            row = dict(zip(header, values))
            try:
                check_row(protocol, row, plan.test[len(rows)])
            except (KeyError, ValueError) as exc:
                raise InputError(f"{path}:{line}: does not match the session's plan ({exc})") from None
            rows.append(row)
    except csv.Error as exc:
        raise InputError(f"{path}: CSV error: {exc}") from None
    return rows


def list_sessions(root: str | os.PathLike[str]) -> tuple[list[SessionInfo], list[str]]:
    """The sessions in a sessions folder.

    Parameters
    ----------
    root : path-like

    Returns
    -------
    sessions : list of SessionInfo
        Oldest first.
    problems : list of str
        Folders with a session.json that cannot be read (one line each).
    """
    base = Path(root).expanduser()
    if not base.is_dir():
        return [], []
    found: list[SessionInfo] = []
    problems: list[str] = []
    try:
        entries = sorted(os.scandir(base), key=lambda e: e.name)[:MAX_LISTED]
    except OSError as exc:
        return [], [f"{base}: cannot list ({exc.strerror or exc})"]
    for entry in entries:
        if (
            entry.name.startswith(".")
            or not entry.is_dir()
            or not os.path.isfile(os.path.join(entry.path, SESSION_FILE))
        ):
            continue
        try:
            with Session.open(entry.path) as session:
                found.append(session.info())
        except InputError as exc:
            problems.append(str(exc))
    found.sort(key=lambda s: (s.created, str(s.folder)))
    return found, problems
