"""The Calibrate tab's routes in a real studio server: bad input refused in one line, nothing written."""

from __future__ import annotations

import json

import pytest

from tests.control.studio.helpers import http
from vibsynth.app.lab.calibrate_tab import SCRIPT, CalibrateService
from vibsynth.control.studio.extension import StudioExtension
from vibsynth.control.studio.server import StudioServer


@pytest.fixture
def calibrate(tmp_path, controller):
    from vibsynth.settings.config import load_config

    config = load_config(None, overrides={"lab.folder": str(tmp_path / "sessions")}, user_file=False)
    service = CalibrateService(config.settings, controller.channels)
    ext = StudioExtension(name="calibrate", title="Calibrate", script=SCRIPT, add_routes=service.add_routes)
    server = StudioServer(controller, port=0, extensions=[ext])
    server.start()
    yield server, service
    server.stop()


def post(server, path, body):
    status, _, data = http(
        server,
        "POST",
        f"/ext/calibrate/{path}",
        body=json.dumps(body).encode(),
        headers={"Content-Type": "application/json", "Origin": f"http://127.0.0.1:{server.port}"},
    )
    return status, json.loads(data)


def test_setup_and_a_view_of_a_profile_without_a_curve(calibrate):
    server, _ = calibrate
    status, _, data = http(server, "GET", "/ext/calibrate/setup")
    setup = json.loads(data)
    assert status == 200 and "hapcoil-example" in setup["profiles"] and setup["sessions"] == []
    status, view = post(server, "view", {"profile": "hapcoil-example", "sessions": []})
    assert status == 200 and view["iso"] is None and view["band_hz"] is None
    assert view["model_band_hz"] == pytest.approx([80.0, 200.7], abs=1.0)  # the paper's band (docs/calibration.md)


@pytest.mark.parametrize(
    "path, body, message",
    [
        ("view", {"profile": "no-such"}, "unknown actuator profile 'no-such'"),
        ("view", {"profile": 3}, "profile: give a profile's name"),
        ("view", {"profile": "flat", "sessions": ["/etc"]}, "/etc: not a session of"),
        ("view", {"profile": "flat", "sessions": "x"}, "sessions: give 0-200 session folders"),
        ("apply", {"profile": "flat", "channel": 0}, "channel must be 1..2"),
        ("apply", {"profile": "flat", "channel": True}, "channel must be 1..2"),
        ("apply", {"profile": "hapcoil-example", "channel": 1}, "is a shipped profile"),
    ],
)
def test_bad_requests_are_refused_in_one_line(calibrate, path, body, message):
    server, service = calibrate
    status, data = post(server, path, body)
    assert status == 400 and message in data["message"] and "\n" not in data["message"]
    assert service.errors == 1
