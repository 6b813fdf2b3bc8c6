"""The studio's spectrum: the model's target at the knobs, and the measured output through the filter bank."""

from __future__ import annotations

import json

import aiohttp
import numpy as np
import pytest

import vibsynth
from tests.control.osc.fakes import FakeEngine
from tests.control.studio.helpers import connect, http, receive_until, run
from vibsynth.control.controller import Controller, KnobLimits
from vibsynth.control.studio.panels import install_panels
from vibsynth.control.studio.server import StudioServer
from vibsynth.control.studio.spectrum import SpectrumModel
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB

FS = 48000.0


@pytest.fixture(scope="module")
def model(basis):
    return SpectrumModel(basis, fs=FS, ceiling_db=DEFAULT_CEILING_DB, range_db=DEFAULT_RANGE_DB)


def test_the_target_is_the_model_shape_at_the_knobs_level(model, basis, rng):
    for balance in np.round(rng.uniform(-2.0, 2.0, 5), 3):  # the model caches balances on a 0.001 grid
        target = model.target_db(0.5, balance)
        shape = basis.spectrum_for_balance(balance)
        assert np.std(target - shape) < 1e-6  # M + t1 V1, only shifted
        # one intensity step moves every band by the mapping's dB per knob unit
        assert np.allclose(model.target_db(0.75, balance) - target, 0.25 * DEFAULT_RANGE_DB)
    assert np.allclose(model.mean_db(0.5), model.target_db(0.5, 0.0))
    assert np.all(np.isneginf(model.target_db(0.0, 1.0)))


def test_the_engines_output_measures_as_the_target(model):
    """A full loop of the real engine's output (vibsynth.render) through the panel's filter bank."""
    for intensity, balance in [(0.6, -1.0), (0.8, 0.0), (0.5, 1.5)]:
        out = vibsynth.render(intensity, balance, 4.0, fs=FS, seed=3)
        measured = model.measured_db(out)
        target = model.target_db(intensity, balance)
        assert np.max(np.abs(measured - target)) < 0.5, (intensity, balance, measured - target)
    assert model.measured_db(np.zeros(100)) is None  # too short to measure the 10 Hz band


def test_measured_band_powers_are_the_filter_banks(model, rng):
    """The panel keeps the filters' responses between measurements: the same numbers as band_powers."""
    from vibsynth.dsp.filterbank import band_powers

    for n in (32768, 32768, 20000):
        x = rng.standard_normal(n)
        expected = band_powers(x, fs=FS, centres=model.basis.centres_hz, order=model.basis.filter_order)
        assert np.allclose(model.measured_powers(x), expected, rtol=1e-10, atol=0)


class TappedEngine(FakeEngine):
    """A fake engine whose output tap plays a real render of whatever the controller last asked."""

    def __init__(self) -> None:
        super().__init__(channels=2, fs=FS)
        self.output = np.zeros((32768, 2), dtype=np.float32)
        self.reads = 0

    def read_output(self, frames: int) -> np.ndarray:
        self.reads += 1
        return self.output[-frames:]


def test_pages_get_the_spectrum_of_their_channel(model):
    engine = TappedEngine()
    controller = Controller(engine, limits=KnobLimits())
    rendered = vibsynth.render(0.7, 0.5, 4.0, fs=FS, seed=1)
    engine.output[:, 1] = rendered[: engine.output.shape[0]]
    server = StudioServer(controller, port=0)
    install_panels(server)
    server.start()
    try:
        spectrum_panel = next(p for p in server.plugins if type(p).__name__ == "SpectrumPanel")
        assert spectrum_panel.computed == 0 and engine.reads == 0  # no page: no work

        async def scenario():
            async with aiohttp.ClientSession() as session:
                ws = await connect(session, server)
                silent = await receive_until(ws, lambda m: m.get("type") == "spectrum" and m["channel"] == 1)
                await ws.send_json({"type": "watch", "channel": 2})
                await ws.send_json({"type": "texture", "channel": 2, "intensity": 0.7, "balance": 0.5})
                pushed = await receive_until(
                    ws,
                    lambda m: (
                        m.get("type") == "spectrum"
                        and m["channel"] == 2
                        and m.get("intensity") == 0.7
                        and m.get("measured_db") is not None
                    ),
                )
                await ws.close()
                return silent, pushed

        silent, pushed = run(scenario())
    finally:
        server.stop()
    assert silent["target_db"] is None and silent["intensity"] == 0.0
    assert len(pushed["target_db"]) == len(pushed["centres_hz"]) == len(pushed["measured_db"]) == 30
    target, measured = np.array(pushed["target_db"]), np.array(pushed["measured_db"])
    assert np.allclose(target, model.target_db(0.7, 0.5), atol=0.01)
    # 0.68 s of the loop: a narrow low band holds a few periods (its level varies by several dB);
    # from 100 Hz up the estimate is within about 1 dB
    start = next(i for i, f in enumerate(pushed["centres_hz"]) if f >= 100.0)
    assert np.max(np.abs(measured - target)[start:]) < 2.0
    assert pushed["intensity_band_hz"] == [80.0, 200.0]
    assert pushed["tap"] is True


def test_the_spectrum_route_checks_its_channel(studio):
    status, _, body = http(studio, "GET", "/api/spectrum?channel=3")
    assert status == 400 and b"channel must be 1..2" in body
    status, _, body = http(studio, "GET", "/api/spectrum?channel=x" + "9" * 100)
    assert status == 400
    status, _, body = http(studio, "GET", "/api/spectrum?channel=1")
    data = json.loads(body)
    assert status == 200 and data["channel"] == 1 and data["tap"] is False and data["measured_db"] is None
