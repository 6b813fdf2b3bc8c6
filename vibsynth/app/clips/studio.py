"""The studio's clip lane: list, edit, save, import and play haptic clips in the browser (docs/clips.md, "The studio").

A studio extension (:mod:`vibsynth.app.studio_tabs`): the tab is ``clip_tab.js`` beside this
file, and its routes live under ``/ext/clips/`` behind the studio's token, Origin, Host and body
checks:

``GET  /ext/clips/list``             every clip (name, origin, duration, counts, loop, tags) and broken files
``GET  /ext/clips/clip/{name}``      one clip as plain data (what its file holds)
``PUT  /ext/clips/clip/{name}``      save the edited clip into the user folder (validated: file-style errors)
``POST /ext/clips/import?file=X``    an AHAP or ``.haptic`` file (the body) as a clip, not saved yet
``POST /ext/clips/play``             ``{"name", "channel", "loop", "clip"?}``: play on a channel (the
                                     edited, unsaved clip when ``clip`` is given)
``POST /ext/clips/stop``             ``{"channel"}``
``GET  /ext/clips/playing?channel=N``  what plays there: name, position in ms, loops left

Playback goes through the service's clip player (:func:`vibsynth.control.clips.player_of`, attached
by the service's clips adapter); without one, play answers an error. File work runs on worker
threads, never on the studio's loop.
"""

from __future__ import annotations

import asyncio
import re
import threading
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from aiohttp import web

from vibsynth.control.clips import player_of
from vibsynth.errors import ClipError, ParameterError, VibsynthError
from vibsynth.formats.ahap import parse_ahap
from vibsynth.formats.haptic_design import HapticDesign
from vibsynth.formats.jsonio import parse_json
from vibsynth.formats.meta_haptic import parse_meta_haptic
from vibsynth.settings.clip_convert import ClipMapping, clip_from_design, clip_name
from vibsynth.settings.clips import Clip, ClipLibrary, UnknownClipError, clip_from_data, load_clip_library
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.models_preset import NAME_PATTERN
from vibsynth.settings.validation import FixedLocator

__all__ = ["NAME", "ClipLane", "StudioClips", "studio_extension"]

NAME = "clips"
#: The tab's ES module.
SCRIPT = Path(__file__).with_name("clip_tab.js")
#: Importers by file suffix.
IMPORTERS: dict[str, Callable[[str, str], HapticDesign]] = {".ahap": parse_ahap, ".haptic": parse_meta_haptic}
#: Unsaved clips the studio keeps for the player at once (the newest per name).
MAX_STUDIO_CLIPS = 32


class StudioClips:
    """The clip player's resolver, wrapped: clips the studio hands over first, then the player's own.

    The studio plays the clip being edited (saved or not) by handing it over under a key no clip
    file can have (``studio:<name>``: ``:`` is not allowed in names), so the player needs no
    new interface and no file clip is ever shadowed.
    """

    PREFIX = "studio:"

    def __init__(self, fallback: Callable[[str], Any]) -> None:
        self.fallback = fallback
        self._clips: OrderedDict[str, Clip] = OrderedDict()
        self._lock = threading.Lock()

    def put(self, clip: Clip) -> str:
        """Keep a clip for the player; returns the name to play it by."""
        key = self.PREFIX + clip.name
        with self._lock:
            self._clips[key] = clip
            self._clips.move_to_end(key)
            while len(self._clips) > MAX_STUDIO_CLIPS:
                self._clips.popitem(last=False)
        return key

    def __call__(self, name: str) -> Any:
        with self._lock:
            clip = self._clips.get(name)
        return clip if clip is not None else self.fallback(name)


def _studio_clips(player: Any) -> StudioClips:
    resolve = player.resolve
    if not isinstance(resolve, StudioClips):
        resolve = StudioClips(resolve)
        player.resolve = resolve
    return resolve


def _error(exc: Exception, status: int = 400) -> web.Response:
    """One line (and the structured problems of a schema error) for the page's error line."""
    problems = [{"key": p.key, "message": p.message, "text": p.text} for p in getattr(exc, "problems", [])]
    return web.json_response({"message": str(exc), "problems": problems}, status=status)


class ClipLane:
    """The routes of the clip lane.

    Parameters
    ----------
    settings : VibsynthConfig
        For the import mapping (``clips:`` and the live balance range of ``knobs:``), made at
        each import: a mapping that does not increase is that request's error.
    controller : Controller
        Its clip player (:func:`~vibsynth.control.clips.player_of`) is looked up at each request.
    library : ClipLibrary
        Shipped + user clips; re-read (only what changed) before each listing and lookup.
    """

    def __init__(self, settings: VibsynthConfig, controller: Any, library: ClipLibrary) -> None:
        self.settings = settings
        self.controller = controller
        self.library = library

    # ----------------------------------------------------------------- helpers
    @staticmethod
    async def _blocking(func: Callable[[], Any]) -> Any:
        return await asyncio.get_running_loop().run_in_executor(None, func)

    async def _body(self, request: web.Request) -> Any:
        text = await request.text()
        return parse_json(text, "request body", error=ClipError)

    def _channel(self, value: Any) -> int:
        channels = int(self.controller.channels)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= channels:
            raise ParameterError(f"channel = {value!r}: no such channel (allowed: 1..{channels})")
        return value - 1

    def _player(self) -> Any:
        player = player_of(self.controller)
        if player is None:
            raise VibsynthError("clips are not available (no clip player is running)")
        return player

    @staticmethod
    def _name(value: Any) -> str:
        if not isinstance(value, str) or not re.fullmatch(NAME_PATTERN, value):
            raise ParameterError(f"clip name {value!r}: not a clip name")
        return value

    def _clip(self, name: str) -> Clip:
        self.library.reload()
        return self.library.get(name)

    @staticmethod
    def _summary(clip: Clip) -> dict[str, Any]:
        return {
            "name": clip.name,
            "origin": clip.origin,
            "duration_ms": clip.duration_ms,
            "keyframes": len(clip.keyframes),
            "transients": len(clip.transients),
            "loop": list(clip.loop) if clip.loop else None,
            "tags": list(clip.tags),
        }

    @staticmethod
    def _guard(handler: Callable[[web.Request], Awaitable[web.StreamResponse]]) -> Any:
        async def guarded(request: web.Request) -> web.StreamResponse:
            try:
                return await handler(request)
            except UnknownClipError as exc:
                return _error(exc, 404)
            except VibsynthError as exc:
                return _error(exc)

        return guarded

    # ----------------------------------------------------------------- routes
    def add_routes(self, app: web.Application, host: Any) -> None:
        """Add the lane's routes (all under ``/ext/clips/``)."""
        prefix = f"/ext/{NAME}/"
        app.router.add_get(prefix + "list", self._guard(self.list))
        app.router.add_get(prefix + "clip/{name}", self._guard(self.get))
        app.router.add_put(prefix + "clip/{name}", self._guard(self.save))
        app.router.add_post(prefix + "import", self._guard(self.import_file))
        app.router.add_post(prefix + "play", self._guard(self.play))
        app.router.add_post(prefix + "stop", self._guard(self.stop))
        app.router.add_get(prefix + "playing", self._guard(self.playing))

    async def list(self, request: web.Request) -> web.StreamResponse:
        def work() -> dict[str, Any]:
            self.library.reload()
            return {
                "clips": [self._summary(c) for c in self.library.clips()],
                "errors": dict(self.library.errors),
                "user_dir": str(self.library.user_dir),
                "playing": player_of(self.controller) is not None,
            }

        return web.json_response(await self._blocking(work))

    async def get(self, request: web.Request) -> web.StreamResponse:
        name = self._name(request.match_info["name"])
        clip = await self._blocking(lambda: self._clip(name))
        return web.json_response({"clip": clip.to_dict(), "origin": clip.origin, "path": str(clip.path)})

    async def save(self, request: web.Request) -> web.StreamResponse:
        name = self._name(request.match_info["name"])
        data = await self._body(request)
        if isinstance(data, dict):
            data = {**data, "name": name}
        clip = clip_from_data(data, FixedLocator(f"clip {name!r}"), name)

        def work() -> Path:
            return self.library.save_user(clip, overwrite=True)

        path = await self._blocking(work)
        return web.json_response({"saved": str(path), "clip": clip.to_dict()})

    async def import_file(self, request: web.Request) -> web.StreamResponse:
        filename = request.query.get("file", "")
        suffix = Path(filename).suffix.lower()
        if suffix not in IMPORTERS or len(filename) > 255:
            raise ClipError(f"{filename or 'the file'}: expected an AHAP (.ahap) or Meta Haptics Studio (.haptic) file")
        raw = await request.read()
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise ClipError(f"{filename}: not a UTF-8 text file") from None

        def work() -> dict[str, Any]:
            design = IMPORTERS[suffix](text, filename)
            clip = clip_from_design(design, clip_name(Path(filename).stem), ClipMapping.from_settings(self.settings))
            return {"clip": clip.to_dict(), "ignored": list(design.ignored)}

        return web.json_response(await self._blocking(work))

    async def play(self, request: web.Request) -> web.StreamResponse:
        body = await self._body(request)
        if not isinstance(body, dict):
            raise ParameterError("play: expected {name, channel, loop, clip}")
        channel = self._channel(body.get("channel"))
        name = self._name(body.get("name"))
        loop = body.get("loop", False)
        if not isinstance(loop, bool):
            raise ParameterError(f"loop = {loop!r}: must be true or false")
        draft = body.get("clip")
        player = self._player()
        if draft is not None:
            if isinstance(draft, dict):
                draft = {**draft, "name": name}
            clip = clip_from_data(draft, FixedLocator(f"clip {name!r}"), name)
        else:
            clip = await self._blocking(lambda: self._clip(name))
        key = _studio_clips(player).put(clip)
        player.play(key, channels=[channel], loops=0 if loop else 1, source="studio")
        return web.json_response({"playing": clip.name, "channel": channel + 1, "loop": loop})

    async def stop(self, request: web.Request) -> web.StreamResponse:
        body = await self._body(request)
        if not isinstance(body, dict):
            raise ParameterError("stop: expected {channel}")
        channel = self._channel(body.get("channel"))
        stopped = self._player().stop(channels=[channel], source="studio")
        return web.json_response({"stopped": int(stopped), "channel": channel + 1})

    async def playing(self, request: web.Request) -> web.StreamResponse:
        raw = request.query.get("channel", "")
        channel = self._channel(int(raw) if raw.isdigit() and len(raw) < 4 else raw)
        player = player_of(self.controller)
        now = None if player is None else player.playing(channel)
        if now is None:
            return web.json_response({"channel": channel + 1, "playing": None})
        return web.json_response(
            {
                "channel": channel + 1,
                "playing": {
                    "name": now.name,
                    "position_ms": float(now.position.clip_ms),
                    "loops_left": int(now.position.loops_left),
                    "started": bool(now.started),
                },
            }
        )


def studio_extension(settings: VibsynthConfig, controller: Any, library: Any, *, config_path: Any = None) -> Any:
    """The clip lane tab (``library`` is the preset library, not used: clips have their own)."""
    from vibsynth.control.studio.extension import StudioExtension

    lane = ClipLane(settings, controller, load_clip_library(settings))
    return StudioExtension(name=NAME, title="Clips", script=SCRIPT, add_routes=lane.add_routes)
