"""The presets panel: the library (shipped + user), a form with the schema's ranges, save, delete, hot reload.

Saving validates the form exactly as a preset file is validated
(:func:`~vibsynth.settings.presets.preset_from_data`: the same model, the same messages;
``problems`` carry the key of every wrong field for the page to show beside it), and writes
only into the user preset folder, atomically, under a plain file name
(:meth:`~vibsynth.settings.library.FileLibrary.user_path` refuses ``../x`` and ``a/b``).
Shipped presets are read-only. Changes of the library (the hot-reload watcher, the command
line, another page) reach open pages within :data:`POLL_S`.

A request naming a ``channel`` saves the sound that channel plays where the form is silent: each
of :data:`KNOB_KEYS` it leaves out (or empty) is taken from the channel's knobs as they are when
the preset is saved (the page leaves them out until the designer types in them or picks a
preset), and the provenance records it (``from_knobs``). Without ``channel`` both are required.

Routes: ``GET /api/presets`` (list, errors, form schema), ``POST /api/presets`` (save),
``DELETE /api/presets/{name}``.
"""

from __future__ import annotations

import asyncio
import re
from dataclasses import replace
from typing import Any

from aiohttp import web

from vibsynth._version import __version__
from vibsynth.control.studio.periodic import WhilePagesOpen
from vibsynth.errors import PresetError
from vibsynth.settings.models_preset import NAME_PATTERN, NAME_RULE, PRESET_VERSION, PresetModel
from vibsynth.settings.presets import Preset, preset_from_data
from vibsynth.settings.validation import InvalidPresetError, model_spec

__all__ = ["FORM_KEYS", "KNOB_KEYS", "POLL_S", "PresetsPanel", "form_schema", "preset_json"]

#: The preset fields the form edits (``name`` is the save-as field; provenance is recorded, not typed).
FORM_KEYS = ("description", "intensity", "balance", "glide_ms", "program", "tags")
#: The fields a request naming a ``channel`` may leave to that channel's knobs (what it plays).
KNOB_KEYS = ("intensity", "balance")
#: Request keys besides the fields: replace an existing user preset; the preset the form started
#: from; the channel (1-based) whose knobs fill the :data:`KNOB_KEYS` the form leaves out.
REQUEST_KEYS = ("name", "overwrite", "like", "channel")
#: How often open pages are checked against the library (in memory: no file is read).
POLL_S = 0.25


def preset_json(preset: Preset) -> dict[str, Any]:
    """A preset for the page: its fields, where it comes from, whether it can be deleted."""
    return {**preset.to_dict(), "origin": preset.origin, "read_only": preset.origin != "user"}


def _bounds(schema: dict[str, Any], defs: dict[str, Any]) -> dict[str, Any]:
    """minimum / maximum / pattern / lengths of a field, looking through ``anyOf`` (optional numbers)."""
    out: dict[str, Any] = {}
    options = [schema, *schema.get("anyOf", [])]
    for option in options:
        if "$ref" in option:
            option = defs.get(option["$ref"].rsplit("/", 1)[-1], {})
        for key in ("type", "minimum", "maximum", "pattern", "maxLength", "maxItems"):
            if key in option and option[key] != "null" and key not in out:
                out[key] = option[key]
        items = option.get("items")
        if isinstance(items, dict) and "pattern" in items and "item_pattern" not in out:
            out["item_pattern"] = items["pattern"]
    return out


def form_schema() -> list[dict[str, Any]]:
    """The form's fields from :class:`PresetModel`: key, help, allowed values, bounds, required."""
    spec = model_spec(PresetModel)
    out = []
    for key in ("name", *FORM_KEYS):
        leaf = spec.leaves[key]
        field = {
            "key": key,
            "help": leaf.help,
            "allowed": spec.allowed(key),
            "required": leaf.required or key == "name",
            "unit": leaf.schema.get("x-unit", ""),
            **_bounds(leaf.schema, spec.defs),
        }
        out.append(field)
    return out


class RequestError(Exception):
    """A refused request: HTTP status, message, and field problems for the form."""

    def __init__(self, status: int, message: str, problems: list[dict[str, str]] | None = None, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.problems = problems or []
        self.extra = extra

    def response(self) -> web.Response:
        return web.json_response({"message": str(self), "problems": self.problems, **self.extra}, status=self.status)


class PresetsPanel:
    """The preset routes and the push of library changes.

    Parameters
    ----------
    server : StudioServer
    library : PresetLibrary or None
    """

    def __init__(self, server: Any, library: Any) -> None:
        self.server = server
        self.library = library
        self._seen: Any = None
        self._poll = WhilePagesOpen(POLL_S, self._tick)
        self.schema = form_schema()
        server.on_pages_changed(self._pages_changed)

    # ------------------------------------------------------------------ state
    def listing(self) -> dict[str, Any]:
        """Every preset, the files that could not be read, the user folder and the form schema."""
        library = self.library
        if library is None:
            return {"type": "presets", "available": False, "presets": [], "errors": [], "schema": self.schema}
        return {
            "type": "presets",
            "available": True,
            "presets": [preset_json(p) for p in library.presets()],
            "errors": [{"file": f, "message": m} for f, m in sorted(library.errors.items())],
            "user_dir": str(library.user_dir) if library.user_dir is not None else None,
            "name_rule": NAME_RULE,
            "schema": self.schema,
        }

    def _signature(self) -> Any:
        if self.library is None:
            return None
        return ([(p, p.origin) for p in self.library.presets()], dict(self.library.errors))

    def push(self) -> None:
        """Send the listing to every page (any thread)."""
        self._seen = self._signature()
        self.server.post(("presets",), self.listing())

    # ------------------------------------------------------------------ hot reload
    def _pages_changed(self, pages: int) -> None:
        self._seen = None  # a page that just came gets the listing at the next tick
        self._poll.pages_changed(pages)

    def _tick(self) -> None:
        if self._signature() != self._seen:
            self.push()

    # ------------------------------------------------------------------ routes
    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/api/presets", self._get)
        app.router.add_post("/api/presets", self._post)
        app.router.add_delete("/api/presets/{name}", self._delete)

    def start(self) -> None:
        """Nothing to start: the poll runs on the studio's loop while pages are open."""

    def stop(self) -> None:
        """Nothing to stop: the poll ends with the studio's loop."""

    async def _get(self, request: web.Request) -> web.StreamResponse:
        return web.json_response(self.listing())

    async def _post(self, request: web.Request) -> web.StreamResponse:
        try:
            data = await request.json()
        except (ValueError, UnicodeDecodeError):
            return RequestError(400, "the body must be a JSON object of preset fields").response()
        return await self._in_worker(self.save, data)

    async def _delete(self, request: web.Request) -> web.StreamResponse:
        return await self._in_worker(self.delete, request.match_info["name"])

    async def _in_worker(self, function: Any, argument: Any) -> web.StreamResponse:
        loop = asyncio.get_running_loop()
        try:
            result = await loop.run_in_executor(self.server.workers, function, argument)
        except RequestError as exc:
            self.server.controller.count_error("studio")
            return exc.response()
        self.push()
        return web.json_response(result)

    # ------------------------------------------------------------------ save / delete (worker threads)
    def _library(self) -> Any:
        if self.library is None:
            raise RequestError(409, "no preset library is loaded (the preset folders could not be read)")
        return self.library

    def save(self, data: Any) -> dict[str, Any]:
        """Validate a form and write it as a user preset; returns ``{"saved", "path", "note"}``.

        Raises
        ------
        RequestError
            400 with ``problems`` (key, message) for wrong fields; 409 when a user preset of
            that name exists and ``overwrite`` is not true (``exists: true``).
        """
        library = self._library()
        if not isinstance(data, dict):
            raise RequestError(400, "the body must be a JSON object of preset fields")
        name = data.get("name")
        if not isinstance(name, str) or not re.fullmatch(NAME_PATTERN, name):
            message = f"preset name {name!r}: must be {NAME_RULE}"
            raise RequestError(400, message, [{"key": "name", "message": f"must be {NAME_RULE}"}])
        overwrite = data.get("overwrite", False)
        like = data.get("like")
        if not isinstance(overwrite, bool) or not (like is None or isinstance(like, str)):
            raise RequestError(400, "overwrite must be true or false and like a preset name")
        fields = {
            k: v for k, v in data.items() if k not in REQUEST_KEYS and k != "provenance" and v is not None and v != ""
        }
        knobs, from_knobs = self._knobs_for(fields, data.get("channel"))
        fields.update(knobs)
        try:
            preset = preset_from_data({"version": PRESET_VERSION, "name": name, **fields}, "studio form", name=name)
        except InvalidPresetError as exc:
            problems = [{"key": p.key, "message": p.message} for p in exc.problems]
            raise RequestError(400, str(exc), problems) from None
        except PresetError as exc:
            raise RequestError(400, str(exc)) from None
        provenance: dict[str, Any] = {}
        if like and like in library:
            provenance = dict(library.get(like).provenance)
            if like != name:
                provenance["edited_from"] = like
        provenance.pop("from_knobs", None)  # the preset it started from may have taken its own
        if from_knobs:
            provenance["from_knobs"] = from_knobs
        provenance["created_by"] = f"vibsynth {__version__} (studio)"
        preset = replace(preset, provenance=provenance)
        return self.write(preset, overwrite=overwrite)

    def _knobs_for(self, fields: dict[str, Any], channel: Any) -> tuple[dict[str, float], dict[str, Any]]:
        """The :data:`KNOB_KEYS` missing from ``fields``, read from a channel's knobs (what it plays).

        Returns
        -------
        values : dict
            key -> the channel's value; empty when nothing is missing or no channel is named.
        provenance : dict
            ``{"channel": N, "keys": [...]}`` when values were taken, else empty.

        Raises
        ------
        RequestError
            400 when ``channel`` is not one of the engine's channels (1-based).
        """
        if channel is None:
            return {}, {}
        count = self.server.controller.channels
        if isinstance(channel, bool) or not isinstance(channel, int) or not 1 <= channel <= count:
            message = f"channel must be an integer 1..{count} (whose knobs fill intensity and balance)"
            raise RequestError(400, f"{message}, got {channel!r}"[:200], [{"key": "channel", "message": message}])
        missing = [k for k in KNOB_KEYS if k not in fields]
        if not missing:
            return {}, {}
        state = self.server.controller.state()[channel - 1]
        return {k: float(getattr(state, k)) for k in missing}, {"channel": channel, "keys": missing}

    def write(self, preset: Preset, *, overwrite: bool) -> dict[str, Any]:
        """Write a validated preset into the user folder (refusing to replace one unless told)."""
        library = self._library()
        try:
            path = library.user_path(preset.name)
            if path.exists() and not overwrite:
                raise RequestError(
                    409, f"a user preset named {preset.name!r} exists; save again to replace it", exists=True
                )
            shipped = preset.name in library and library.get(preset.name).origin == "shipped"
            library.save_user(preset, overwrite=True)
        except PresetError as exc:
            raise RequestError(400, str(exc)) from None
        note = f"saved {preset.name}" + (" (it overrides the shipped preset of that name)" if shipped else "")
        return {"saved": preset.name, "path": str(path), "note": note}

    def delete(self, name: str) -> dict[str, Any]:
        """Delete a user preset; returns ``{"deleted", "note"}``."""
        library = self._library()
        if not re.fullmatch(NAME_PATTERN, name):
            raise RequestError(400, f"preset name {name!r}: must be {NAME_RULE} (not a path)")
        try:
            path, shipped_again = library.remove_user(name)
        except PresetError as exc:
            status = 404 if str(exc).startswith("unknown") else 409
            raise RequestError(status, str(exc)) from None
        note = f"deleted {path.name}" + ("; the shipped preset of that name is used again" if shipped_again else "")
        return {"deleted": name, "note": note}
