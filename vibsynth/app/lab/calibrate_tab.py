"""The studio's Calibrate tab (issue 25 item 4): a profile's response, a lab's iso-intensity curve, the band.

Routes (JSON; behind the studio's token, Origin, Host and body-size checks):

``GET  /ext/calibrate/setup``  channels, the profile in use, the profiles, the lab's iso-intensity sessions
``POST /ext/calibrate/view``   ``{profile, sessions}``: the response (dB vs Hz), the curve in acceleration
                               (``sessions``: lab folders on sines, may be empty), the band it derives and the
                               band of the model curve
``POST /ext/calibrate/apply``  ``{channel, profile, sessions}``: write the derived weighting and band into the
                               (user) profile (:func:`vibsynth.app.calibrate.apply_iso_curve`) and, hot, give
                               the channel that profile: its trim (:mod:`vibsynth.engine.trims`) is derived
                               against the running bank and glided in; the answer says what the config needs
                               to keep it (``actuator.channel_profiles``), which is not written

Errors answer 400 with ``{"message": ...}`` (one line), are counted, and change nothing.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from vibsynth.control.studio.extension import StudioExtension, StudioHost
from vibsynth.errors import InputError, ParameterError
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["CalibrateService", "studio_extension", "SCRIPT"]

log = logging.getLogger(__name__)

SCRIPT = Path(__file__).with_name("static") / "calibrate_tab.js"
#: Sessions one view may combine.
MAX_SESSIONS = 200


class CalibrateService:
    """What the Calibrate tab shows and writes.

    Parameters
    ----------
    settings : VibsynthConfig
    channels : int
        The engine's channels.
    engine : Engine, optional
        The running engine, to trim a channel for the profile applied to it (None: only the file is written).
    """

    def __init__(
        self, settings: VibsynthConfig, channels: int, engine: Any = None, *, config_path: Path | None = None
    ) -> None:
        from vibsynth.research.lab.session import sessions_root
        from vibsynth.settings.layouts import channel_profile_names

        self.settings = settings
        self.channels = channels
        self.engine = engine
        self.root = sessions_root(settings.lab)
        self.errors = 0
        self.config_path = config_path
        #: each channel's profile as applied so far (the config's, then every "apply to channel")
        self.assigned: list[str | None] = list(channel_profile_names(settings))

    def setup(self) -> dict[str, Any]:
        """Channels, the profile in use, the profiles and the lab's iso-intensity sessions."""
        from vibsynth.research.lab.session import list_sessions
        from vibsynth.settings.actuators import actuator_profiles

        sessions = [
            s.to_dict()
            for s in list_sessions(self.root)[0]
            if s.protocol == "intensity" and s.set_kind == "sines" and s.done > 0
        ]
        return {
            "channels": self.channels,
            "profile": self.settings.actuator.profile,
            "profiles": sorted(actuator_profiles()),
            "sessions": sessions,
        }

    def _profile(self, body: dict[str, Any]) -> dict[str, Any]:
        from vibsynth.settings.actuators import load_actuator_profile

        name = body.get("profile")
        if not isinstance(name, str) or not 0 < len(name) <= 200:
            raise ParameterError("profile: give a profile's name")
        return load_actuator_profile(name)

    def _curve(self, body: dict[str, Any], response: list[list[float]]) -> Any:
        from vibsynth.research.lab.iso import iso_curve
        from vibsynth.research.lab.session import Session, list_sessions

        folders = body.get("sessions") or []
        if not isinstance(folders, list) or len(folders) > MAX_SESSIONS or not all(isinstance(f, str) for f in folders):
            raise ParameterError(f"sessions: give 0-{MAX_SESSIONS} session folders")
        if not folders:
            return None
        known = {str(s.folder) for s in list_sessions(self.root)[0]}
        unknown = [f for f in folders if f not in known]
        if unknown:
            raise InputError(f"{unknown[0][:200]}: not a session of {self.root}")
        sessions = [Session.open(f) for f in folders]
        try:
            return iso_curve(sessions, response=response)
        finally:
            for s in sessions:
                s.close()

    def view(self, body: dict[str, Any]) -> dict[str, Any]:
        """The profile's response, the sessions' curve in acceleration, and the bands."""
        from vibsynth.app.calibrate import profile_band

        profile = self._profile(body)
        response = [list(map(float, p)) for p in profile["response"]]
        curve = self._curve(body, response)
        _, model_band = profile_band(response)
        out: dict[str, Any] = {
            "profile": profile["name"],
            "absolute": bool(profile.get("absolute")),
            "response": response,
            "model_band_hz": model_band,
            "stored_band_hz": profile.get("band_hz"),
            "iso": None,
            "band_hz": None,
        }
        if curve is not None:
            _, band = profile_band(response, curve.freqs_hz, curve.acceleration_db)
            out["iso"] = {
                "frequency_hz": curve.freqs_hz.tolist(),
                "acceleration_db": curve.acceleration_db.tolist(),
                "voltage_db": curve.mean_db.tolist(),
                "participants": curve.participants,
                "reference_hz": curve.reference_hz,
            }
            out["band_hz"] = band
        return out

    def apply(self, body: dict[str, Any]) -> dict[str, Any]:
        """Write the sessions' band into the channel's profile (a user profile: shipped ones are read-only)."""
        from vibsynth.app.calibrate import apply_iso_curve
        from vibsynth.settings.actuators import user_profile_dir

        channel = body.get("channel")
        if isinstance(channel, bool) or not isinstance(channel, int) or not 1 <= channel <= self.channels:
            raise ParameterError(f"channel must be 1..{self.channels}")
        profile = self._profile(body)
        path = Path(profile["file"])
        if path.parent.resolve() != user_profile_dir().resolve():
            raise InputError(
                f"{profile['name']} is a shipped profile: measure your actuator (vibsynth calibrate response) "
                "and apply the curve to that profile"
            )
        self._check_fits(profile)
        curve = self._curve(body, [list(map(float, p)) for p in profile["response"]])
        if curve is None:
            raise ParameterError("choose the iso-intensity sessions whose curve to apply")
        who = ", ".join(curve.participants)[:120]
        written = apply_iso_curve(
            path, curve.freqs_hz, curve.acceleration_db, source=f"lab iso-intensity curve ({who}), channel {channel}"
        )
        out = {"profile": profile["name"], "channel": channel, "band_hz": written["band_hz"], "file": str(path)}
        return out | self._retrim(channel, profile["name"])

    def _check_fits(self, profile: dict[str, Any]) -> None:
        """Refuse (before writing anything) a profile the running engine cannot trim a channel for."""
        from vibsynth.engine.trims import TrimContext
        from vibsynth.settings.actuators import profile_rate_problem

        problem = profile_rate_problem(profile, self.settings.audio.rate)
        if problem is not None:
            raise InputError(problem)
        context = getattr(self.engine, "trim_context", None)
        if isinstance(context, TrimContext) and bool(profile.get("absolute")) != context.reference.absolute:
            kinds = ("relative", "measured (absolute)")
            raise InputError(
                f"{profile['name']} is {kinds[bool(profile.get('absolute'))]} but the engine's bank was built for a "
                f"{kinds[context.reference.absolute]} response: their responses cannot be compared"
            )

    def _retrim(self, channel: int, name: str) -> dict[str, Any]:
        """Give the running engine's channel this profile now (its trim) and keep it: the config line
        ``actuator.channel_profiles`` with every channel's profile, written into the user's config."""
        from vibsynth.engine.actuator import ActuatorResponse
        from vibsynth.engine.trims import ChannelActuator, TrimContext, retrim_channel
        from vibsynth.settings.actuators import load_actuator_profile, profile_intensity

        names = list(self.assigned)
        names[channel - 1] = name
        out: dict[str, Any] = {"applied": False}
        context = getattr(self.engine, "trim_context", None)
        if isinstance(context, TrimContext):
            profile = load_actuator_profile(name)
            response = ActuatorResponse.from_points(
                profile["response"], max_boost_db=context.max_gain_db, absolute=bool(profile["absolute"])
            )
            trim = retrim_channel(
                self.engine, context, channel - 1, ChannelActuator(name, response, profile_intensity(name))
            )
            out = {"applied": True, "trim": trim.describe()}
        self.assigned = names
        out["config"] = "actuator.channel_profiles: [" + ", ".join(n or "null" for n in names) + "]"
        return out | self._keep(names)

    def _keep(self, names: list[str | None]) -> dict[str, Any]:
        """Write ``actuator.channel_profiles`` into the user's config: ``{"saved": FILE}``, or why not."""
        from vibsynth.errors import ConfigError
        from vibsynth.settings.config_write import write_config_key

        if self.config_path is None:
            return {"saved": None}
        try:
            path = write_config_key(self.config_path, "actuator.channel_profiles", names)
        except (ConfigError, OSError) as exc:
            self.errors += 1
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            log.warning("calibrate: the channel's profile plays but was not saved: %s", why)
            return {"saved": None, "save_error": why}
        log.info("calibrate: actuator.channel_profiles written to %s", path)
        return {"saved": str(path)}

    # ------------------------------------------------------------------ HTTP
    def add_routes(self, app: Any, host: StudioHost) -> None:
        """The routes under ``/ext/calibrate/``."""
        from vibsynth.app.lab.studio import json_handler

        def handler(work: Any, *, body: bool = True) -> Any:
            return json_handler(work, self._refuse, body=body)

        app.router.add_get("/ext/calibrate/setup", handler(lambda _: self.setup(), body=False))
        app.router.add_post("/ext/calibrate/view", handler(self.view))
        app.router.add_post("/ext/calibrate/apply", handler(self.apply))

    def _refuse(self, message: str) -> Any:
        from aiohttp import web

        self.errors += 1
        log.info("calibrate: refused: %s", message)
        return web.json_response({"message": message.splitlines()[0] if message else "refused"}, status=400)


def studio_extension(
    settings: VibsynthConfig, controller: Any, library: Any, *, config_path: Path | None = None
) -> StudioExtension | None:
    """The Calibrate tab (``vibsynth/app/studio_tabs.py`` lists this module); "apply to channel"
    writes ``actuator.channel_profiles`` into ``config_path`` (None: it only answers the line)."""
    service = CalibrateService(
        settings, int(controller.channels), getattr(controller, "engine", None), config_path=config_path
    )
    return StudioExtension(name="calibrate", title="Calibrate", script=SCRIPT, add_routes=service.add_routes)
