"""The Follow panel: the live follower's input, level, gate, gain, range, focus and trace, and per-channel on/off.

Routes (behind the studio's token, Origin and body checks, like every route):

``GET /api/follow``          the panel's state: ``running``, the snapshot of the running
                             :class:`~vibsynth.control.follow.follower.Follower` (device, state,
                             input peak, tracked level, gate, gain, range, focus, routes), the
                             whole trace, the ranges of the typed settings, how to start follow
``GET /api/follow/devices``  the input devices PortAudio lists (the input picker)
``POST /api/follow``         one change per request, a JSON object with one of:
                             ``{"gain_db": dB}``, ``{"gate_db": dB}``, ``{"range_db": dB}``,
                             ``{"focus": "all|effects|bass|beat"}``, ``{"channel": n, "on": bool}``,
                             ``{"device": NAME}``

A change goes through the follower's setters, the ones OSC ``/vibsynth/follow/...`` and
``/vibsynth/ch/{n}/follow`` call (their ranges are the typed settings' :func:`~vibsynth.settings.models.bounds_of`,
delivered to the page in ``limits``): a bad value is answered 400 with one line naming the range,
counted (the studio's refusals, reason ``follow``, and the controller's ``studio`` errors), and
nothing changes. More than :data:`CHANGE_RATE` changes a second are refused (429, ``flood``).

``device`` switches the follow input (or starts follow when ``serve`` ran without ``--follow``):
only a device PortAudio lists as an input is taken, by its exact name; a file is never named
from the browser (a page could make the service read any file it can reach: follow a file with
``serve --follow FILE.wav``). The new input gets the ``follow:`` section of the config with
the live gain, gate, focus and range carried over; every route starts on. When the new input
cannot be opened the answer says why and the previous input is reopened.

While a page is open, ``{"type": "follow", ...}`` is pushed every :data:`PUSH_PERIOD_S`: the
snapshot and the trace points of the last :data:`PUSH_TRACE_S` (the page merges them by time).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import threading
from collections.abc import Sequence
from typing import Any

from aiohttp import web

from vibsynth.control import follow as follow_registry
from vibsynth.control.follow.follower import HISTORY_STEP_S, Follower
from vibsynth.control.osc.follow import NOT_RUNNING
from vibsynth.control.studio.commands import Throttle
from vibsynth.control.studio.periodic import WhilePagesOpen
from vibsynth.dsp.follow import FOCUSES
from vibsynth.errors import ParameterError, VibsynthError
from vibsynth.settings.models import bounds_of

__all__ = ["FollowPanel", "PUSH_PERIOD_S", "PUSH_TRACE_S", "CHANGE_RATE", "parse_change", "follow_limits"]

log = logging.getLogger(__name__)

#: How often open pages get the follow state.
PUSH_PERIOD_S = 0.1
#: Trace pushed each time: the newest this many seconds (several pushes overlap: one coalesced away loses nothing).
PUSH_TRACE_S = 0.5
#: Changes a second the panel takes (burst as many); a slider sends at most ~20.
CHANGE_RATE = 50.0
#: Largest change request body (one key and a value).
MAX_CHANGE_BYTES = 2048
#: Refusal reason counted in the studio's status.
REASON = "follow"
#: Longest device name taken.
MAX_DEVICE_CHARS = 256
#: The numeric changes and their typed setting.
NUMBERS = {"gain_db": "follow.gain_db", "gate_db": "follow.gate_db", "range_db": "follow.range_db"}
KEYS = (*NUMBERS, "focus", "channel", "device")
#: What the panel says when follow does not run.
HOW_TO_START = NOT_RUNNING + "; or pick an input here"


class ChangeError(ParameterError):
    """A malformed or out-of-range change (answered 400)."""


def follow_limits() -> dict[str, Any]:
    """The ranges of the panel's controls, from the typed settings (one definition)."""
    out: dict[str, Any] = {}
    for key, setting in NUMBERS.items():
        low, high = bounds_of(setting)
        out[key] = [float(low or 0.0), float(high or 0.0)]
    out["focus"] = list(FOCUSES)
    return out


def _show(value: Any) -> str:
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:39] + "…"


def parse_change(body: bytes, channels: int) -> tuple[str, Any]:
    """Validate one change request: ``(key, value)``; ranges are checked by the follower's setters.

    Parameters
    ----------
    body : bytes
        The request body (a JSON object with exactly one of :data:`KEYS`; ``channel`` comes with ``on``).
    channels : int
        The engine's channel count (``channel`` is 1-based).

    Raises
    ------
    ChangeError
        Not JSON, not an object, no or several changes, an unknown key, a mistyped value.
    """
    if len(body) > MAX_CHANGE_BYTES:
        raise ChangeError(f"request of {len(body)} bytes is over the limit of {MAX_CHANGE_BYTES}")
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise ChangeError('not JSON: send an object like {"gain_db": 3}') from None
    if not isinstance(data, dict):
        raise ChangeError('a change must be a JSON object like {"gain_db": 3}')
    unknown = [k for k in data if k not in (*KEYS, "on")]
    if unknown:
        raise ChangeError(f"unknown key {_show(unknown[0])}; known: {', '.join(KEYS)} (channel with on)")
    given = [k for k in KEYS if k in data]
    if len(given) != 1:
        raise ChangeError(f"one change per request: one of {', '.join(KEYS)}, got {len(given)}")
    key = given[0]
    value = data[key]
    if "on" in data and key != "channel":
        raise ChangeError('on goes with channel: {"channel": 1, "on": false}')
    if key in NUMBERS:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ChangeError(f"{key} must be a finite number (dB), got {_show(value)}")
        return key, float(value)
    if key == "focus":
        if value not in FOCUSES:
            raise ChangeError(f"focus must be one of {', '.join(FOCUSES)}, got {_show(value)}")
        return key, value
    if key == "channel":
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= channels:
            raise ChangeError(f"channel must be an integer 1..{channels}, got {_show(value)}")
        on = data.get("on")
        if not isinstance(on, bool):
            raise ChangeError(f"on must be true or false, got {_show(on)}")
        return key, (value - 1, on)
    if not isinstance(value, str) or not 1 <= len(value.strip()) <= MAX_DEVICE_CHARS:
        raise ChangeError(
            f"device must be an input device's name (1-{MAX_DEVICE_CHARS} characters), got {_show(value)}"
        )
    return key, value.strip()


def _trace(follower: Follower, since: float | None) -> dict[str, list[list[Any]]]:
    """The trace points per route label, ``[t s, level dB, intensity, balance, gate]``, newer than ``since``."""
    out = {}
    for label, points in follower.history().items():
        out[label] = [
            [round(t, 4), round(level, 2), round(i, 4), round(b, 4), bool(g)]
            for t, level, i, b, g in points
            if since is None or t > since
        ]
    return out


class FollowPanel:
    """The Follow panel's routes and push (see the module notes).

    Parameters
    ----------
    server : StudioServer
    settings : VibsynthConfig, optional
        The typed settings: without them (a studio built by hand) the panel can show and change a
        running follower but not start or switch an input.
    servers : sequence
        The running control servers; the follow service among them is the one switched.
    list_inputs : callable, optional
        ``() -> list of device dicts`` (default :func:`vibsynth.engine.outputs.list_devices` of kind input).
    open_source : callable, optional
        ``open_source(device) -> InputSource`` (default: the one ``follow.device`` would name; tests).
    """

    def __init__(
        self,
        server: Any,
        settings: Any = None,
        servers: Sequence[Any] = (),
        *,
        list_inputs: Any = None,
        open_source: Any = None,
    ) -> None:
        self.server = server
        self.settings = settings
        self.service = next((s for s in servers if getattr(s, "name", "") == "follow"), None)
        self.started: Any = None  # a follow service this panel started (stopped with the studio)
        self.list_inputs = list_inputs or _list_inputs
        self.open_source = open_source
        self.throttle = Throttle(rate=CHANGE_RATE, burst=CHANGE_RATE)
        self._switching = threading.Lock()
        self.last_error = ""
        self.changes = 0
        server.on_pages_changed(WhilePagesOpen(PUSH_PERIOD_S, self._push).pages_changed)

    # ------------------------------------------------------------------ state
    @property
    def follower(self) -> Follower | None:
        return follow_registry.follower_of(self.server.controller)

    def state(self, *, trace_since: float | None = None, full_trace: bool = True) -> dict[str, Any]:
        """The panel's message: ``running``, ``snapshot``, ``trace``, ``limits``, ``can_start``, ``hint``."""
        follower = self.follower
        message: dict[str, Any] = {
            "type": "follow",
            "running": follower is not None,
            "limits": follow_limits(),
            "can_start": self.settings is not None,
            "hint": "" if follower is not None else HOW_TO_START if self.settings is not None else NOT_RUNNING,
            "error": self.last_error,
            "trace_step_s": HISTORY_STEP_S,
            "full": full_trace,
        }
        if follower is not None:
            message["snapshot"] = follower.snapshot()
            message["trace"] = _trace(follower, None if full_trace else trace_since)
        return message

    def _push(self) -> None:
        follower = self.follower
        since = None
        if follower is not None:
            ends = [points[-1][0] for points in follower.history().values() if points]
            since = max(ends, default=0.0) - PUSH_TRACE_S
        self.server.post(("follow",), self.state(trace_since=since, full_trace=False))

    # ------------------------------------------------------------------ routes
    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/api/follow", self._get)
        app.router.add_get("/api/follow/devices", self._devices)
        app.router.add_post("/api/follow", self._post)

    def start(self) -> None:
        """Nothing to start: the push runs while pages are open."""

    def stop(self) -> None:
        """Stop the follow service this panel started (the one serve started stops with serve)."""
        if self.started is not None:
            try:
                self.started.stop()
            except VibsynthError as exc:
                log.warning("stopping follow: %s", exc)
            self.started = None

    async def _get(self, request: web.Request) -> web.StreamResponse:
        return web.json_response(self.state())

    async def _devices(self, request: web.Request) -> web.StreamResponse:
        loop = asyncio.get_running_loop()
        try:
            devices = await loop.run_in_executor(self.server.workers, self.list_inputs)
        except VibsynthError as exc:
            return web.json_response({"devices": [], "message": f"no input devices: {exc}"})
        follower = self.follower
        current = follower.input_status().get("device", "") if follower is not None else ""
        return web.json_response({"devices": devices, "current": str(current), "can_start": self.settings is not None})

    def refuse(self, status: int, message: str, reason: str = REASON) -> web.Response:
        """Count a refused change and answer it with one line."""
        gate = self.server.gate
        if gate is not None:
            gate.count(reason)
        self.server.controller.count_error("studio")
        return web.json_response({"message": message}, status=status)

    async def _post(self, request: web.Request) -> web.StreamResponse:
        body = await request.read()
        if not self.throttle.take():
            return self.refuse(429, "too many follow changes: slow down", "flood")
        try:
            key, value = parse_change(body, self.server.controller.channels)
        except ChangeError as exc:
            return self.refuse(400, str(exc))
        if key == "device":
            return await self._switch_request(str(value))
        follower = self.follower
        if follower is None:
            return self.refuse(409, HOW_TO_START)
        try:
            if key == "gain_db":
                follower.set_gain(value)
            elif key == "gate_db":
                follower.set_gate(value)
            elif key == "range_db":
                follower.set_range(value)
            elif key == "focus":
                follower.set_focus(value)
            else:
                follower.set_channel(value[0], value[1])
        except VibsynthError as exc:
            return self.refuse(400, str(exc))
        self.changes += 1
        self._push()
        return web.json_response(self.state(full_trace=False, trace_since=math.inf))

    # ------------------------------------------------------------------ switching the input
    async def _switch_request(self, device: str) -> web.StreamResponse:
        if self.settings is None:
            return self.refuse(409, "this studio cannot start or switch follow inputs (no settings given to it)")
        if not self._switching.acquire(blocking=False):
            return self.refuse(409, "an input switch is already under way; wait for it")
        try:
            loop = asyncio.get_running_loop()
            try:
                await loop.run_in_executor(self.server.workers, self.switch, device)
            except VibsynthError as exc:
                self.last_error = str(exc)
                return self.refuse(400, str(exc))
        finally:
            self._switching.release()
        self.last_error = ""
        self.changes += 1
        self._push()
        return web.json_response(self.state(full_trace=False, trace_since=math.inf))

    def switch(self, device: str) -> None:
        """Follow the input device named ``device`` (exactly as listed); blocking (a worker thread).

        Raises
        ------
        ParameterError
            No listed input device has that name.
        DeviceError, InputError, ConfigError
            The device cannot be opened (the previous input is reopened).
        """
        from vibsynth.control.follow import service as follow_service

        names = [str(d.get("name", "")) for d in self.list_inputs()]
        if device not in names:
            shown = ", ".join(repr(n) for n in names[:12]) or "none"
            raise ParameterError(f"no input device named {device!r}; inputs: {shown}")
        settings = self.settings
        follower = self.follower
        update: dict[str, Any] = {"enabled": True, "device": device}
        if follower is not None:
            live = follower.live
            update.update(gain_db=live.gain_db, gate_db=live.gate_db, focus=live.focus, range_db=live.range_db)
        follow = settings.follow.model_copy(update=update)
        fresh = follow_service.create(
            settings.model_copy(update={"follow": follow}),
            self.server.controller,
            basis=None if follower is None else follower.basis,
            source=None if self.open_source is None else self.open_source(device),
        )
        if fresh is None:  # not reachable: enabled is set above
            raise ParameterError("follow could not be started")
        current = self.service or self.started
        if current is not None:
            current.stop()
        try:
            fresh.start()
        except VibsynthError as exc:
            fresh.stop()
            if current is not None:
                try:
                    current.start()
                except VibsynthError as again:
                    log.warning("follow: the previous input did not reopen either: %s", again)
                    raise type(exc)(f"{exc} (and the previous input did not reopen: {again})") from None
            raise
        log.info("follow: the studio switched the input to %s", device)
        if self.service is not None:
            self.service.follower = fresh.follower  # serve stops the service: it stops the follower it holds now
        else:
            self.started = fresh


def _list_inputs() -> list[dict[str, Any]]:
    """The input devices PortAudio lists: name, index, channels, host API name."""
    from vibsynth.engine.outputs import list_devices

    apis, devices = list_devices(kind="input")
    names = {a["index"]: str(a.get("name", "")) for a in apis}
    return [
        {
            "name": str(d.get("name", "")),
            "index": int(d["index"]),
            "channels": int(d.get("max_input_channels", 0)),
            "host_api": names.get(d.get("hostapi"), ""),
        }
        for d in devices
    ]
