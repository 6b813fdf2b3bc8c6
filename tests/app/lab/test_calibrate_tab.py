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


# ---------------------------------------------------------------- apply to channel, hot
def _user_profile(name, *, absolute=True, rate=16000, gain=0.0):
    from vibsynth.settings.actuators import user_profile_dir

    folder = user_profile_dir()
    folder.mkdir(parents=True, exist_ok=True)
    rate_line = f"rate: {rate}\n" if rate else ""
    path = folder / f"{name}.yaml"
    path.write_text(
        f"name: {name}\nabsolute: {str(absolute).lower()}\n{rate_line}"
        f"response: [[10, {gain - 25}], [60, {gain + 8}], [150, {gain}], [1000, {gain}]]\n"
    )
    return path


@pytest.fixture
def trimmed(tmp_path, monkeypatch, engine, controller, basis):
    """A Calibrate service over an engine whose bank was built for a measured (absolute) flat response."""
    from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING
    from vibsynth.engine.actuator import ActuatorResponse
    from vibsynth.engine.trims import TrimContext
    from vibsynth.settings.config import load_config

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    reference = ActuatorResponse.from_points([(10, 0), (1000, 0)], absolute=True)
    engine.trim_context = TrimContext(basis, reference, PAPER_WEIGHTING, 40.0)
    overrides = {"lab.folder": str(tmp_path / "sessions"), "audio.rate": 16000, "audio.channels": 2}
    config = load_config(None, overrides=overrides, user_file=False)
    service = CalibrateService(config.settings, controller.channels, engine, config_path=tmp_path / "vibsynth.yaml")
    ext = StudioExtension(name="calibrate", title="Calibrate", script=SCRIPT, add_routes=service.add_routes)
    server = StudioServer(controller, port=0, extensions=[ext])
    server.start()
    yield server, service, engine
    server.stop()


def test_applying_a_profile_to_a_channel_trims_it_now(trimmed):
    _, service, engine = trimmed
    _user_profile("coil-b", gain=-6.0)
    done = service._retrim(2, "coil-b")
    engine.render(2048)  # past the 50 ms glide
    assert done["applied"] is True and done["config"] == "actuator.channel_profiles: [null, coil-b]"
    (off1, gain1), (off2, gain2) = engine.trim_values()
    assert (off1, gain1) == (0.0, 1.0)  # the other channel is untouched
    assert off2 < -0.05 and gain2 > 1.2  # low end 25 dB down (felt brighter), 6 dB less sensitive
    assert "gain +" in done["trim"]


def test_apply_to_channel_is_kept_in_the_config_with_its_comments(trimmed, tmp_path):
    from vibsynth.settings.config import load_config
    from vibsynth.settings.layouts import channel_profile_names

    _, service, _ = trimmed
    config = tmp_path / "vibsynth.yaml"
    config.write_text("# my rig\naudio: {rate: 16000, channels: 2}  # two coils\nactuator:\n  max_boost_db: 40\n")
    _user_profile("coil-a")
    _user_profile("coil-b", gain=-6.0)
    assert service._retrim(2, "coil-b")["saved"] == str(config)
    done = service._retrim(1, "coil-a")  # the second apply keeps the first
    assert done["config"] == "actuator.channel_profiles: [coil-a, coil-b]" and done["saved"] == str(config)
    text = config.read_text()
    assert "# my rig" in text and "# two coils" in text and "max_boost_db: 40" in text
    assert "channel_profiles: [coil-a, coil-b]" in text
    assert channel_profile_names(load_config(config, user_file=False).settings) == ["coil-a", "coil-b"]


def test_a_config_that_cannot_be_written_keeps_the_trim_and_says_why(trimmed, tmp_path):
    _, service, engine = trimmed
    config = tmp_path / "vibsynth.yaml"
    config.write_text("a: &x [1]\nb: *x\n")  # an alias: the loader refuses the file
    before = config.read_bytes()
    _user_profile("coil-b", gain=-6.0)
    done = service._retrim(2, "coil-b")
    engine.render(2048)
    assert done["applied"] is True and done["saved"] is None and "alias" in done["save_error"]
    assert "\n" not in done["save_error"] and config.read_bytes() == before and service.errors == 1
    assert engine.trim_values()[1] != (0.0, 1.0)  # it plays: only the saving failed


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"absolute": False, "rate": None}, "coil-c is relative but the engine's bank was built for a measured"),
        ({"rate": 44100}, "was measured at 44100 Hz but audio.rate is 16000 Hz"),
    ],
)
def test_a_profile_the_engine_cannot_trim_for_is_refused_before_anything_is_written(trimmed, kw, message):
    server, service, engine = trimmed
    path = _user_profile("coil-c", **kw)
    before = path.read_bytes()
    status, data = post(server, "apply", {"profile": "coil-c", "channel": 1, "sessions": []})
    assert status == 400 and message in data["message"] and "\n" not in data["message"]
    assert path.read_bytes() == before and engine.trim_values()[0] == (0.0, 1.0) and service.errors == 1
