"""The recording panel: upload a WAV, see its analysis beside the model, make a preset of it.

``POST /api/recording`` takes the WAV as the request body (``Content-Type: audio/wav``, the
file's name in ``X-Filename``), at most :data:`~vibsynth.control.studio.security.UPLOAD_CAP`
bytes: a larger ``Content-Length`` is refused before anything is read, and a body without
one is cut off at the cap. The file is analysed exactly as ``vibsynth analyze`` does
(:func:`~vibsynth.formats.recordings.read_recording`, :func:`~vibsynth.dsp.analysis.analyze`)
on a worker thread, one upload at a time. The answer holds intensity, balance, t1..t8, the
band spectrum beside ``M + t1 V1`` at the recording's level, and the non-stationarity flag;
``POST /api/recording/{id}/preset`` saves it as a user preset (the knobs and the provenance
of ``vibsynth preset from-recording``: :func:`~vibsynth.settings.from_recording.preset_from_analysis`).
The last :data:`KEPT` analyses are kept for that, in memory; nothing of the upload is kept on disk.
"""

from __future__ import annotations

import asyncio
import os
import re
import secrets
import tempfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np
from aiohttp import web

from vibsynth.control.studio.presets import PresetsPanel, RequestError
from vibsynth.control.studio.security import UPLOAD_CAP
from vibsynth.dsp.analysis import Analysis, analyze, variant_spectra
from vibsynth.dsp.basis import Basis
from vibsynth.errors import InputError, ParameterError, PresetError
from vibsynth.formats.recordings import read_recording
from vibsynth.settings.from_recording import preset_from_analysis, recording_digest
from vibsynth.settings.models_preset import NAME_PATTERN, NAME_RULE

__all__ = ["KEPT", "NON_STATIONARY_DB", "RecordingPanel", "UPLOAD_PATH"]

UPLOAD_PATH = "/api/recording"
#: Analyses kept for "make preset" (the newest).
KEPT = 8
#: Non-stationarity (std of the 100 ms intensity level, the paper's metric) above which a recording
#: is flagged as not stationary: stationary noise shaped like the database measures 0.6-1.2 dB, a
#: 10 dB on/off modulation 4.3 dB; the perceptual model describes stationary vibrations only.
NON_STATIONARY_DB = 3.0
_CHUNK = 1 << 16


@dataclass(frozen=True)
class _Kept:
    analysis: Analysis
    file_name: str
    digest: str


def _file_name(header: str | None) -> str:
    """The uploaded file's name, for the description and provenance: its last part, printable, short."""
    text = os.path.basename(unquote(header or "").replace("\\", "/"))
    text = "".join(ch for ch in text if ch.isprintable())[:128].strip()
    return text or "upload.wav"


def _stem_name(file_name: str) -> str:
    """A preset name proposed from a file name (letters, digits, . _ - only)."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", Path(file_name).stem).strip("-.") or "recording"
    return stem[:64] if re.fullmatch(NAME_PATTERN, stem[:64]) else "recording"


def _db_list(values: Any) -> list[float]:
    return [round(float(v), 2) for v in np.asarray(values, dtype=np.float64)]


class RecordingPanel:
    """Upload, analysis and "make preset" of a recording.

    Parameters
    ----------
    server : StudioServer
    presets : PresetsPanel
        Writes the preset (user folder only) and tells the pages.
    basis : Basis
    ceiling_db, range_db : float
        The engine's intensity mapping (the analysis gives the knob under it).
    """

    def __init__(self, server: Any, presets: PresetsPanel, basis: Basis, ceiling_db: float, range_db: float) -> None:
        self.server = server
        self.presets = presets
        self.basis = basis
        self.ceiling_db = float(ceiling_db)
        self.range_db = float(range_db)
        self._kept: OrderedDict[str, _Kept] = OrderedDict()
        self._busy: asyncio.Semaphore | None = None

    def add_routes(self, app: web.Application) -> None:
        app.router.add_post(UPLOAD_PATH, self._upload)
        app.router.add_post(UPLOAD_PATH + "/{ident}/preset", self._make_preset)

    def start(self) -> None:
        """Nothing to start."""

    def stop(self) -> None:
        """Nothing to stop."""

    # ------------------------------------------------------------------ upload
    async def _read_body(self, request: web.Request) -> bytes:
        """The body, at most :data:`UPLOAD_CAP` bytes (the gate refused a larger Content-Length already)."""
        data = bytearray()
        while True:
            chunk = await request.content.read(_CHUNK)
            if not chunk:
                return bytes(data)
            data += chunk
            if len(data) > UPLOAD_CAP:
                raise RequestError(413, f"the upload is over the limit of {UPLOAD_CAP} bytes")

    async def _upload(self, request: web.Request) -> web.StreamResponse:
        if self._busy is None:
            self._busy = asyncio.Semaphore(1)
        if self._busy.locked():
            return RequestError(429, "another recording is being analysed; try again in a moment").response()
        async with self._busy:
            try:
                data = await self._read_body(request)
                if not data:
                    raise RequestError(400, "the request body is empty: send the WAV file's bytes")
                name = _file_name(request.headers.get("X-Filename"))
                loop = asyncio.get_running_loop()
                result = await loop.run_in_executor(self.server.workers, self.analyse, data, name)
            except RequestError as exc:
                gate = self.server.gate
                if exc.status == 413 and gate is not None:
                    gate.count("too_large")
                self.server.controller.count_error("studio")
                response = exc.response()
                if exc.status == 413:  # do not read the rest of an over-long body: close the connection
                    response.force_close()
                return response
        return web.json_response(result)

    def analyse(self, data: bytes, file_name: str) -> dict[str, Any]:
        """Analyse an uploaded WAV (worker thread); returns what the panel shows."""
        with tempfile.TemporaryDirectory(prefix="vibsynth-studio-") as folder:
            path = Path(folder) / "upload.wav"
            path.write_bytes(data)
            try:
                recording = read_recording(path)
                result = analyze(
                    recording.samples,
                    fs=recording.fs,
                    basis=self.basis,
                    ceiling_db=self.ceiling_db,
                    range_db=self.range_db,
                )
            except (InputError, ParameterError) as exc:
                message = str(exc).replace(str(path), file_name)
                raise RequestError(400, message) from None
        ident = secrets.token_hex(8)
        self._kept[ident] = _Kept(result, file_name, recording_digest(data))
        while len(self._kept) > KEPT:
            self._kept.popitem(last=False)
        s1 = variant_spectra(result, self.basis)["S1"]
        level = float(np.mean(result.band_db))  # M + t1 V1 is level-free: shown at the recording's mean level
        return {
            "id": ident,
            "file": file_name,
            "duration_s": round(result.duration_s, 4),
            "fs": result.fs,
            "intensity": round(result.intensity_knob, 4),
            "intensity_in_range": 0.0 <= result.intensity_knob <= 1.0,
            "balance": round(result.balance, 4),
            "level_db": round(result.level_db, 3),
            "t1": round(result.t1, 4),
            "scores": [round(float(s), 4) for s in result.scores],
            "outside_database": bool(result.outside_database),
            "non_stationarity_db": round(result.non_stationarity_db, 3),
            "stationary": result.non_stationarity_db <= NON_STATIONARY_DB,
            "non_stationary_threshold_db": NON_STATIONARY_DB,
            "centres_hz": [round(float(f), 3) for f in self.basis.centres_hz],
            "band_db": _db_list(result.band_db),
            "model_db": _db_list(s1 + level),
            "suggested_name": _stem_name(file_name),
        }

    # ------------------------------------------------------------------ make a preset
    async def _make_preset(self, request: web.Request) -> web.StreamResponse:
        try:
            body = await request.json()
        except (ValueError, UnicodeDecodeError):
            return RequestError(400, 'the body must be a JSON object like {"name": "my-texture"}').response()
        ident = request.match_info["ident"]
        loop = asyncio.get_running_loop()
        try:
            result = await loop.run_in_executor(self.server.workers, self.make_preset, ident, body)
        except RequestError as exc:
            self.server.controller.count_error("studio")
            return exc.response()
        self.presets.push()
        return web.json_response(result)

    def make_preset(self, ident: str, body: Any) -> dict[str, Any]:
        """Save an analysed recording as a user preset (worker thread)."""
        kept = self._kept.get(ident)
        if kept is None:
            raise RequestError(404, "that analysis is no longer kept: upload the recording again")
        if not isinstance(body, dict):
            raise RequestError(400, 'the body must be a JSON object like {"name": "my-texture"}')
        name = body.get("name")
        overwrite = body.get("overwrite", False)
        if not isinstance(name, str) or not re.fullmatch(NAME_PATTERN, name):
            raise RequestError(
                400, f"preset name {name!r}: must be {NAME_RULE}", [{"key": "name", "message": f"must be {NAME_RULE}"}]
            )
        if not isinstance(overwrite, bool):
            raise RequestError(400, "overwrite must be true or false")
        try:
            made = preset_from_analysis(
                kept.analysis,
                name=name,
                recording=kept.file_name,
                digest=kept.digest,
                basis_id=self.basis.id,
                ceiling_db=self.ceiling_db,
                range_db=self.range_db,
                created_by="studio",
            )
        except PresetError as exc:
            raise RequestError(400, str(exc)) from None
        saved = self.presets.write(made.preset, overwrite=overwrite)
        saved["warnings"] = list(made.warnings) + list(made.notes)
        saved["preset"] = {"intensity": made.preset.intensity, "balance": made.preset.balance}
        return saved
