"""The studio's Lab tab: its routes under ``/ext/lab/`` and the :class:`LabService` behind them.

Routes (JSON in and out; behind the studio's token, Origin, Host and body-size checks):

``GET  /ext/lab/setup``           protocols, stimulus sets, defaults, sessions, the run's state
``POST /ext/lab/start``           ``{protocol, stimuli, folder, participant, seed, familiarisation, channel,
                                  reference, method}``
``POST /ext/lab/open``            ``{folder}``: resume a session from its CSV
``POST /ext/lab/play``            ``{slot, gain}``: the trial again (pair, stimulus at gain, a slot's version)
``POST /ext/lab/play-reference``  the reference (intensity) or the original (resynthesis)
``POST /ext/lab/gain``            ``{gain}``: the slider moved (the stimulus plays on at it)
``POST /ext/lab/answer``          ``{value}``, ``{ratings: {slot: rating}}`` or ``{judgement}`` (staircase); next trial
``POST /ext/lab/pause``, ``/resume``, ``/stop``
``GET  /ext/lab/state``           the run's state (never a stimulus' name)
``POST /ext/lab/analyze``         ``{folders}``: one or more sessions' results
``POST /ext/lab/equalise``        ``{folders}``: intensity sessions' gains -> a stimulus set under sets/
``GET  /ext/lab/lab.css``         the tab's styles

Every change of the run is pushed to every page as ``{"type": "ext", "extension": "lab",
"key": "state", "data": state}``. Errors answer 400 with ``{"message": ...}`` (one line), are
counted, and change nothing.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from vibsynth.app.lab.runner import LabRunner
from vibsynth.control.studio.extension import StudioExtension, StudioHost
from vibsynth.errors import InputError, ParameterError, VibsynthError
from vibsynth.research.lab.build import SessionRequest, new_session
from vibsynth.research.lab.protocol import MAX_SEED, PROTOCOLS, LabParameters, check_seed
from vibsynth.research.lab.session import Session, list_sessions, sessions_root
from vibsynth.research.lab.stimuli import DEFAULT_SINES_HZ, RENDERS_DEFAULT_COUNT, SINE_REFERENCE_HZ, load_set
from vibsynth.settings.models_config import Knobs, VibsynthConfig
from vibsynth.settings.models_lab import Lab

__all__ = ["LabService", "studio_extension", "STATIC"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
#: Text fields of a request: at most this long (a folder path, a participant id, a seed).
MAX_FIELD = 4096
#: Sets written by "store as an equalised set" go here, under the sessions folder.
SETS_FOLDER = "sets"


def _field(body: dict[str, Any], key: str, kind: type | tuple[type, ...], *, required: bool = True) -> Any:
    value = body.get(key)
    if value is None and not required:
        return None
    if isinstance(value, bool) or not isinstance(value, kind):
        raise ParameterError(f"{key}: expected {getattr(kind, '__name__', 'a value')}, got {type(value).__name__}")
    if isinstance(value, str) and len(value) > MAX_FIELD:
        raise ParameterError(f"{key}: longer than {MAX_FIELD} characters")
    return value


def _number(body: dict[str, Any], key: str) -> float:
    value = _field(body, key, (int, float))
    if not math.isfinite(value):
        raise ParameterError(f"{key} must be a finite number")
    return float(value)


class LabService:
    """The lab as the studio offers it: sessions made and run on the service's engine.

    Parameters
    ----------
    lab : Lab
        The typed ``lab:`` section (sessions folder, protocol defaults).
    knobs : Knobs
        The typed ``knobs:`` section (the level mapping).
    controller : Controller
        Its engine plays the stimuli.
    library : PresetLibrary or None
        The presets a stimulus set may name.
    basis : Basis, optional
        Default: the shipped basis.
    """

    def __init__(self, lab: Lab, knobs: Knobs, controller: Any, library: Any, *, basis: Any = None) -> None:
        from vibsynth.formats.basis_file import default_basis

        self.lab = lab
        self.knobs = knobs
        self.root = sessions_root(self.lab)
        self.library = library
        self.basis = basis if basis is not None else default_basis()
        self.controller = controller
        self.host: StudioHost | None = None
        self.runner = LabRunner(controller.engine, controller, on_change=self._publish)
        self.errors = 0
        self._busy = threading.Lock()  # one session being prepared at a time
        self._preparing = False

    # ------------------------------------------------------------------ state and setup
    def _publish(self, state: dict[str, Any]) -> None:
        if self.host is not None:
            self.host.publish("lab", "state", state)

    def state(self) -> dict[str, Any]:
        """The run's state; ``preparing`` while a session's stimuli are being made."""
        state = self.runner.state()
        if self._preparing:
            state["status"] = "preparing"
        return state

    def parameters(self, **overrides: Any) -> LabParameters:
        """The ``lab:`` section's parameters with a request's overrides."""
        return LabParameters.from_settings(self.lab, **overrides)

    def setup(self) -> dict[str, Any]:
        """What the set-up form offers: protocols, stimulus sets, defaults, sessions."""
        sessions, problems = list_sessions(self.root)
        folders: list[str] = []
        for info in sessions:
            if info.set_kind == "folder" and info.set_name not in folders:
                folders.append(info.set_name)
        sets_dir = self.root / SETS_FOLDER
        if sets_dir.is_dir():
            for entry in sorted(sets_dir.iterdir())[:200]:
                if entry.is_dir() and str(entry) not in folders:
                    folders.append(str(entry))
        n_presets = len(self.library.presets()) if self.library is not None else 0
        sets = [{"value": "presets", "label": f"Presets ({n_presets})"}] if n_presets else []
        sets.append({"value": "renders", "label": f"Engine renders ({RENDERS_DEFAULT_COUNT} balances, -1..+1)"})
        sets.append(
            {
                "value": "sines",
                "label": f"Sines: iso-intensity curve ({len(DEFAULT_SINES_HZ)} from 10 to 1000 Hz vs "
                f"{SINE_REFERENCE_HZ:g} Hz; intensity protocol)",
            }
        )
        sets += [{"value": f, "label": f} for f in folders]
        return {
            "protocols": list(PROTOCOLS),
            "sets": sets,
            "defaults": {**self.parameters().to_dict(), "seed_max": str(MAX_SEED)},
            "channels": self.controller.channels,
            "root": str(self.root),
            "sessions": [s.to_dict() for s in sessions],
            "problems": problems,
            "state": self.state(),
        }

    # ------------------------------------------------------------------ starting
    def start(self, body: dict[str, Any]) -> dict[str, Any]:
        """Make a session from the form and run it (slow: renders and analyses the stimuli)."""
        protocol = _field(body, "protocol", str)
        spec = (_field(body, "folder", str, required=False) or "").strip() or _field(body, "stimuli", str)
        participant = _field(body, "participant", str)
        seed = check_seed(_field(body, "seed", (str, int)))
        familiarisation = _field(body, "familiarisation", int, required=False)
        channel = _field(body, "channel", int, required=False) or 0
        channels = self._channels(channel)
        reference = (_field(body, "reference", str, required=False) or "").strip() or "noise"
        method = _field(body, "method", str, required=False) or "adjustment"
        request = SessionRequest(
            protocol,
            participant,
            seed,
            self.parameters(familiarisation_pairs=familiarisation),
            reference=reference,
            method=method,
        )
        if not self._busy.acquire(blocking=False):
            raise InputError("a session is being prepared")
        try:
            if self.runner.running:
                raise InputError("a session is already running: stop it first")
            self.runner.clear_done()  # a failed start shows the set-up again, not the last session's end
            self._preparing = True
            self._publish(self.state())
            p = request.parameters
            stimuli = load_set(
                spec,
                presets=self._presets,
                fs=float(self.controller.engine.fs),
                seconds=p.stimulus_s,
                seed=seed,
                basis=self.basis,
                ceiling_db=self.knobs.ceiling_db,
                range_db=self.knobs.range_db,
                render_intensity=p.level,
            )
            session = new_session(
                self.root,
                request,
                stimuli,
                basis=self.basis,
                ceiling_db=self.knobs.ceiling_db,
                range_db=self.knobs.range_db,
                limiter_ceiling=self.knobs.limiter_ceiling,
            )
            self._preparing = False
            try:
                return self.runner.start(session, channels=channels)
            except BaseException:
                session.close()
                raise
        finally:
            self._preparing = False
            self._busy.release()
            self._publish(self.state())

    def open(self, body: dict[str, Any]) -> dict[str, Any]:
        """Resume a session of the sessions folder from its CSV."""
        folder = Path(_field(body, "folder", str))
        known = {str(s.folder) for s in list_sessions(self.root)[0]}
        if str(folder) not in known:
            raise InputError(f"{folder}: not a session of {self.root}")
        if not self._busy.acquire(blocking=False):
            raise InputError("a session is being prepared")
        try:
            if self.runner.running:
                raise InputError("a session is already running: stop it first")
            session = Session.open(folder, write=True)
            channel = _field(body, "channel", int, required=False) or 0
            try:
                return self.runner.start(session, channels=self._channels(channel))
            except BaseException:
                session.close()
                raise
        finally:
            self._busy.release()

    def _channels(self, channel: int) -> list[int] | None:
        if channel == 0:
            return None
        if not 1 <= channel <= self.controller.channels:
            raise ParameterError(f"channel must be 0 (all) or 1..{self.controller.channels}, got {channel}")
        return [channel - 1]

    def _presets(self) -> list[Any]:
        return list(self.library.presets()) if self.library is not None else []

    # ------------------------------------------------------------------ during a run
    def play(self, body: dict[str, Any]) -> dict[str, Any]:
        slot = _field(body, "slot", int, required=False)
        gain = _number(body, "gain") if body.get("gain") is not None else None
        return self.runner.play(slot=slot, gain=gain)

    def answer(self, body: dict[str, Any]) -> dict[str, Any]:
        judgement = _field(body, "judgement", str, required=False)
        if judgement is not None:
            return self.runner.answer(judgement=judgement[:20])
        ratings = _field(body, "ratings", dict, required=False)
        if ratings is not None:
            parsed: dict[int, float] = {}
            for key, value in ratings.items():
                if not str(key).isdecimal() or len(str(key)) > 2:
                    raise ParameterError(f"ratings: slot {str(key)[:10]!r} is not a slot number")
                parsed[int(key)] = _number({"rating": value}, "rating")
            return self.runner.answer(ratings=parsed)
        return self.runner.answer(value=_number(body, "value"))

    # ------------------------------------------------------------------ results
    def _sessions(self, body: dict[str, Any]) -> list[Session]:
        folders = _field(body, "folders", list)
        if not folders or len(folders) > 200 or not all(isinstance(f, str) for f in folders):
            raise ParameterError("folders: give 1-200 session folders")
        known = {str(s.folder) for s in list_sessions(self.root)[0]}
        unknown = [f for f in folders if f not in known]
        if unknown:
            raise InputError(f"{unknown[0]}: not a session of {self.root}")
        return [Session.open(f) for f in folders]

    def analyze(self, body: dict[str, Any]) -> dict[str, Any]:
        """One or more sessions' results (the protocol's analysis, as JSON)."""
        from vibsynth.research.lab.analysis import analyze_dissimilarity, analyze_intensity, analyze_resynthesis

        sessions = self._sessions(body)
        try:
            protocol = sessions[0].protocol
            if protocol == "intensity":
                from vibsynth.research.lab.iso import is_sine_session, iso_curve

                out = analyze_intensity(sessions).to_dict()
                if all(is_sine_session(s) for s in sessions):
                    out["iso"] = iso_curve(sessions).to_dict()
                return out
            if protocol == "dissimilarity":
                result = analyze_dissimilarity(sessions, basis=self.basis, n_splits=100, components=False)
                return result.to_dict()
            return analyze_resynthesis(sessions).to_dict()
        finally:
            for s in sessions:
                s.close()

    def equalise(self, body: dict[str, Any]) -> dict[str, Any]:
        """Store intensity sessions' mean gains as a stimulus set under ``<sessions>/sets/``."""
        from vibsynth.research.lab.analysis import analyze_intensity, write_equalised_set

        sessions = self._sessions(body)
        try:
            if sessions[0].protocol != "intensity":
                raise InputError("only intensity sessions give gains to equalise a set with")
            result = analyze_intensity(sessions)
            stamp = datetime.now(timezone.utc).astimezone().strftime("%Y%m%d-%H%M%S")
            name = f"equalised-{'-'.join(sorted({s.participant for s in sessions}))[:80]}-{stamp}"
            folder = write_equalised_set(result, sessions, self.root / SETS_FOLDER / name)
            return {"folder": str(folder), "stimuli": len(result.ids)}
        finally:
            for s in sessions:
                s.close()

    # ------------------------------------------------------------------ HTTP
    def add_routes(self, app: Any, host: StudioHost) -> None:
        """The routes under ``/ext/lab/`` (the studio calls this once at start)."""
        self.host = host

        def handler(work: Any, *, body: bool = True) -> Any:
            return json_handler(work, self._refuse, body=body)

        r = app.router
        r.add_get("/ext/lab/setup", handler(lambda _: self.setup(), body=False))
        r.add_get("/ext/lab/state", handler(lambda _: self.state(), body=False))
        r.add_get("/ext/lab/lab.css", self._css)
        r.add_post("/ext/lab/start", handler(self.start))
        r.add_post("/ext/lab/open", handler(self.open))
        r.add_post("/ext/lab/play", handler(self.play))
        r.add_post("/ext/lab/play-reference", handler(lambda _: self.runner.play_reference()))
        r.add_post("/ext/lab/gain", handler(self._gain))
        r.add_post("/ext/lab/answer", handler(self.answer))
        r.add_post("/ext/lab/pause", handler(lambda _: self.runner.pause()))
        r.add_post("/ext/lab/resume", handler(lambda _: self.runner.resume()))
        r.add_post("/ext/lab/stop", handler(lambda _: self.runner.stop()))
        r.add_post("/ext/lab/analyze", handler(self.analyze))
        r.add_post("/ext/lab/equalise", handler(self.equalise))

    def _gain(self, body: dict[str, Any]) -> dict[str, Any]:
        self.runner.set_gain(_number(body, "gain"))
        return {"ok": True}

    def _refuse(self, message: str) -> Any:
        from aiohttp import web

        self.errors += 1
        log.info("lab: refused: %s", message)
        return web.json_response({"message": message.splitlines()[0] if message else "refused"}, status=400)

    async def _css(self, request: Any) -> Any:
        from aiohttp import web

        return web.Response(text=(STATIC / "lab.css").read_text(encoding="utf-8"), content_type="text/css")


def json_handler(work: Any, refuse: Any, *, body: bool = True) -> Any:
    """An aiohttp handler running ``work(body_dict)`` in an executor: its result as JSON, a
    :class:`VibsynthError` (or a body that is no JSON object) as ``refuse(message)``."""
    from aiohttp import web

    async def handle(request: Any) -> Any:
        data: dict[str, Any] = {}
        if body and request.can_read_body:
            try:
                data = await request.json()
            except ValueError:
                return refuse("the request body is not JSON")
            if not isinstance(data, dict):
                return refuse("the request body must be a JSON object")
        try:
            result = await asyncio.get_running_loop().run_in_executor(None, work, data)
        except VibsynthError as exc:
            return refuse(str(exc))
        return web.json_response(result)

    return handle


def studio_extension(
    settings: VibsynthConfig, controller: Any, library: Any, *, config_path: Any = None
) -> StudioExtension | None:
    """The Lab tab (``vibsynth/app/studio_tabs.py`` lists this module): ``lab:`` and ``knobs:``."""
    service = LabService(settings.lab, settings.knobs, controller, library)
    return StudioExtension(name="lab", title="Lab", script=STATIC / "lab_tab.js", add_routes=service.add_routes)
