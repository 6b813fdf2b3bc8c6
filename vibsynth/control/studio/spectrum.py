"""The spectrum panel: the model's target beside what the engine really outputs, per channel.

* **target**: the 30-band spectrum ``M + t1(balance) V1`` of the basis (the perceptual
  model), placed at the level the engine renders for the intensity: the intensity knob
  gives the 80-200 Hz level (:func:`~vibsynth.dsp.intensity.knob_to_level_db`), and the
  engine's synthesis (:meth:`~vibsynth.dsp.synthesis.SpectralShaper.solve_balance`, what the
  noise bank is built with) gives the band levels of that spectrum at that level. Within the
  balance range the filter bank can measure, these equal the model's shape exactly; beyond
  it (about -4..+2.3 on the default basis) the engine saturates, and the measured curve
  shows it.
* **mean**: ``M`` at the same level, for reference.
* **measured**: the newest second of the engine's output on that channel
  (``engine.read_output``), through the same 30-band filter bank as ``vibsynth analyze``
  (:func:`~vibsynth.dsp.filterbank.bin_powers` and
  :func:`~vibsynth.dsp.filterbank.bandpass_response`, as :func:`~vibsynth.dsp.filterbank.band_powers`
  combines them; the responses are kept for the window length).

A worker thread computes them a few times a second, only while a page is open, for the
channels the open pages watch, and pushes ``{"type": "spectrum", ...}``; ``GET
/api/spectrum?channel=N`` answers the same on request.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections import OrderedDict
from typing import Any

import numpy as np
from aiohttp import web
from numpy.typing import NDArray

from vibsynth.dsp.basis import Basis, to_db
from vibsynth.dsp.filterbank import bandpass_response, bin_powers
from vibsynth.dsp.intensity import INTENSITY_BAND_HZ, SILENCE_DB, knob_to_level_db
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.engine.engine import TAP_MAX_FRAMES
from vibsynth.errors import ParameterError

__all__ = ["MEASURE_PERIOD_S", "SpectrumModel", "SpectrumPanel"]

log = logging.getLogger(__name__)

#: How often the measured spectrum is recomputed while pages are open.
MEASURE_PERIOD_S = 0.25
#: A knob change recomputes the target at most this often.
TARGET_MIN_PERIOD_S = 0.03
#: Output analysed per measurement: this long, capped by the output tap (32768 frames: 0.68 s at 48 kHz).
MEASURE_SECONDS = 1.0
#: Shortest output analysed: 3 periods of the lowest band.
MIN_MEASURE_SECONDS = 0.3
#: Measurements averaged (band powers, running mean over the last ~this many while the knobs stay):
#: one window of 0.68 s holds about one period's worth of the narrow low bands, far too noisy alone.
AVERAGE_OVER = 8
#: Balances are cached to this step (knob units): finer than any slider moves.
BALANCE_STEP = 1e-3
#: Cached target shapes.
CACHE_SIZE = 256


def _json_db(values: NDArray[np.float64] | None) -> list[float | None] | None:
    """dB levels for JSON: silence (or below :data:`SILENCE_DB`) as null, 0.01 dB precision."""
    if values is None:
        return None
    return [round(float(v), 2) if math.isfinite(v) and v > SILENCE_DB else None for v in values]


class _Settling(Exception):
    """The output window still holds audio from before the last knob move: no measurement yet."""


class SpectrumModel:
    """Target and measured 30-band spectra of an engine's channels.

    Parameters
    ----------
    basis : Basis
        The basis the engine's bank was built from.
    fs : float
        The engine's rate.
    ceiling_db, range_db : float
        The engine's intensity mapping.
    """

    def __init__(self, basis: Basis, fs: float, ceiling_db: float, range_db: float) -> None:
        self.basis = basis
        self.fs = float(fs)
        self.ceiling_db = float(ceiling_db)
        self.range_db = float(range_db)
        self._shaper: SpectralShaper | None = None
        self._shapes: OrderedDict[int, NDArray[np.float64]] = OrderedDict()
        self._responses: dict[int, NDArray[np.float64]] = {}
        self._lock = threading.Lock()

    @property
    def centres_hz(self) -> NDArray[np.float64]:
        return np.asarray(self.basis.centres_hz, dtype=np.float64)

    def _offset_shape(self, balance: float) -> NDArray[np.float64]:
        """``M + t1 V1`` at an 80-200 Hz level of 0 dB, placed as the engine's synthesis places it."""
        key = int(round(balance / BALANCE_STEP))
        with self._lock:
            cached = self._shapes.get(key)
            if cached is not None:
                self._shapes.move_to_end(key)
                return cached
            if self._shaper is None:
                n = int(round(self.fs * MEASURE_SECONDS))
                self._shaper = SpectralShaper(
                    fs=self.fs, n_samples=n, centres=self.basis.centres_hz, order=self.basis.filter_order
                )
            shaper = self._shaper
            b = key * BALANCE_STEP
            ideal = self.basis.spectrum_for_balance(b)
            realised = shaper.weights_band_db(shaper.solve_balance(self.basis, b, level_db=0.0))
            shape = np.asarray(ideal + float(np.mean(realised - ideal)), dtype=np.float64)
            self._shapes[key] = shape
            if len(self._shapes) > CACHE_SIZE:
                self._shapes.popitem(last=False)
            return shape

    def level_db(self, intensity: float) -> float:
        """80-200 Hz level (dB) the engine renders for an intensity knob (``-inf`` at 0)."""
        return knob_to_level_db(
            min(1.0, max(0.0, float(intensity))), ceiling_db=self.ceiling_db, range_db=self.range_db
        )

    def target_db(self, intensity: float, balance: float) -> NDArray[np.float64]:
        """Band levels (dB), shape (n_bands,), of ``M + t1 V1`` at these knobs (``-inf`` when silent)."""
        return self._offset_shape(float(balance)) + self.level_db(intensity)

    def mean_db(self, intensity: float) -> NDArray[np.float64]:
        """Band levels (dB), shape (n_bands,), of the mean spectrum ``M`` at this intensity."""
        return self._offset_shape(0.0) + self.level_db(intensity)

    def measured_db(self, samples: NDArray[np.floating[Any]]) -> NDArray[np.float64] | None:
        """Band levels (dB), shape (n_bands,), of output samples, shape (frames,); None when too short."""
        powers = self.measured_powers(samples)
        return None if powers is None else to_db(powers)

    def measured_powers(self, samples: NDArray[np.floating[Any]]) -> NDArray[np.float64] | None:
        """Band powers, shape (n_bands,), of output samples, shape (frames,); None when too short."""
        x = np.asarray(samples, dtype=np.float64)
        if x.size < int(MIN_MEASURE_SECONDS * self.fs):
            return None
        try:
            freqs, power = bin_powers(x, fs=self.fs)
        except ParameterError:
            return None
        # band_powers' sum of bin power x |H_k|^2, with the filters' responses on these bins computed
        # once per window length (42 ms of work that would otherwise hold the GIL every measurement)
        response = self._responses.get(freqs.size)
        if response is None:
            response = np.ascontiguousarray(
                bandpass_response(freqs, centres=self.basis.centres_hz, order=self.basis.filter_order)
            )
            self._responses = {freqs.size: response}
        return np.asarray(response @ power, dtype=np.float64)

    def y_range_db(self) -> tuple[float, float]:
        """A fixed dB axis covering every intensity: from 40 dB below the quietest level to 25 dB above the ceiling."""
        low = self.ceiling_db - self.range_db - 40.0
        high = self.ceiling_db + 25.0
        return 10.0 * math.floor(low / 10.0), 10.0 * math.ceil(high / 10.0)


class SpectrumPanel:
    """Computes the spectra of the watched channels on a worker thread and pushes them.

    Parameters
    ----------
    server : StudioServer
    model : SpectrumModel
    """

    def __init__(self, server: Any, model: SpectrumModel) -> None:
        self.server = server
        self.model = model
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._watched: frozenset[int] = frozenset()
        self._last_knobs: dict[int, tuple[float, float]] = {}
        # channel -> (knobs measured, measurements averaged, mean band powers, monotonic time the window is clean)
        self._averages: dict[int, tuple[tuple[float, float, bool], int, NDArray[np.float64], float]] = {}
        self._last_measure = 0.0
        self.computed = 0
        server.on_pages_changed(self._pages_changed)
        self._unsubscribe = server.controller.subscribe(self._knob_changed)

    # ------------------------------------------------------------------ routes
    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/api/spectrum", self._get)

    async def _get(self, request: web.Request) -> web.StreamResponse:
        text = request.query.get("channel", "1")
        channels = self.server.controller.channels
        if not text.isdigit() or not 1 <= int(text) <= channels:
            return web.json_response({"message": f"channel must be 1..{channels}, got {text[:20]!r}"}, status=400)
        data = await asyncio.get_running_loop().run_in_executor(self.server.workers, self.spectrum, int(text) - 1)
        return web.json_response(data)

    # ------------------------------------------------------------------ computing
    def spectrum(self, channel: int, measure: bool = True) -> dict[str, Any]:
        """The spectrum message of a 0-based channel (on a worker thread: it analyses output)."""
        state = self.server.controller.state()[channel]
        model = self.model
        intensity, balance = float(state.intensity), float(state.balance)
        silent = intensity <= 0.0
        target = None if silent else model.target_db(intensity, balance)
        mean = None if silent else model.mean_db(intensity)
        settling = False
        measured = None
        if measure:
            try:
                measured = self._measure(channel)
            except _Settling:
                settling = True
        low, high = model.y_range_db()
        self.computed += 1
        return {
            "type": "spectrum",
            "channel": channel + 1,
            "intensity": intensity,
            "balance": balance,
            "muted": bool(state.muted),
            "centres_hz": [round(float(f), 3) for f in model.centres_hz],
            "target_db": _json_db(target),
            "mean_db": _json_db(mean),
            "measured_db": _json_db(measured),
            "measured": measure and measured is not None,
            "settling": settling,
            "tap": callable(getattr(self.server.controller.engine, "read_output", None)),
            "intensity_band_hz": list(INTENSITY_BAND_HZ),
            "y_range_db": [low, high],
        }

    def _measure(self, channel: int) -> NDArray[np.float64] | None:
        """Band levels (dB) of the channel's newest output, averaged while its knobs stay where they are.

        Raises :class:`_Settling` while the analysis window still holds audio from before the
        last knob move (the window's length plus the glide): the page keeps its last curve.
        """
        engine = self.server.controller.engine
        read = getattr(engine, "read_output", None)
        if not callable(read):
            return None
        frames = min(TAP_MAX_FRAMES, int(round(self.model.fs * MEASURE_SECONDS)))
        try:
            block = np.asarray(read(frames))
        except Exception as exc:  # noqa: BLE001 - a failing tap leaves the measured curve empty
            log.debug("studio: reading the output tap failed: %s", exc)
            return None
        if block.ndim != 2 or not 0 <= channel < block.shape[1]:
            return None
        powers = self.model.measured_powers(block[:, channel])
        if powers is None:
            return None
        state = self.server.controller.state()[channel]
        knobs = (float(state.intensity), float(state.balance), bool(state.muted))
        now = time.monotonic()
        previous = self._averages.get(channel)
        if previous is None or previous[0] != knobs:
            # The window still holds what played before the move (and its glide): wait until it does not.
            settle = frames / self.model.fs + float(state.glide_s)
            self._averages[channel] = (knobs, 0, np.zeros_like(powers), now + settle)
            raise _Settling
        _, count, mean, settled_at = previous
        if now < settled_at:
            raise _Settling
        count = min(count + 1, AVERAGE_OVER)
        mean = mean + (powers - mean) / count
        self._averages[channel] = (knobs, count, mean, settled_at)
        return to_db(mean)

    # ------------------------------------------------------------------ the worker
    def _pages_changed(self, pages: int) -> None:
        hub = self.server.hub
        self._watched = frozenset(p.channel for p in hub.pages) if hub is not None else frozenset()
        self._last_knobs.clear()  # a page that starts watching gets its spectrum at once
        self._wake.set()

    def _knob_changed(self, event: Any) -> None:
        if event.channel in self._watched and event.name in ("intensity", "balance", "mute"):
            self._wake.set()

    def start(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="vibsynth-studio-spectrum", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._unsubscribe()
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._watched:
                self._wake.wait()  # nothing to do without a page: no CPU at all
                self._wake.clear()
                continue
            self._wake.wait(MEASURE_PERIOD_S)
            self._wake.clear()
            if self._stop.is_set():
                break
            try:
                self._round()
            except Exception:  # noqa: BLE001 - keep the panel alive whatever one round does
                log.exception("studio: computing a spectrum failed")
            time.sleep(TARGET_MIN_PERIOD_S)  # rate limit: a dragged slider costs at most ~30 targets/s

    def _round(self) -> None:
        now = time.monotonic()
        measure = now - self._last_measure >= MEASURE_PERIOD_S * 0.9
        states = self.server.controller.state()
        for channel in sorted(self._watched):
            knobs = (states[channel].intensity, states[channel].balance)
            if not measure and self._last_knobs.get(channel) == knobs:
                continue
            self._last_knobs[channel] = knobs
            message = self.spectrum(channel, measure=measure)
            if not measure or message["settling"]:  # keep the last measured curve on the page meanwhile
                message.pop("measured_db")
                message.pop("measured")
            self.server.post(("spectrum", channel), message)
        if measure:
            self._last_measure = now
