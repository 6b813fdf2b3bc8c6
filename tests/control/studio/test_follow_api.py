"""The studio's Follow API: state, changes through the follower's setters, bad input refused and counted, switching.

A real engine, controller and follower (a fake input the test writes into, stepped by hand:
tests/control/follow), behind a real studio server on a free port.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.control.follow.conftest import FS, Rig
from tests.control.follow.fakes import FakeInput, tone
from tests.control.studio.helpers import connect, http, origin, receive_until, run
from vibsynth.control import follow as registry
from vibsynth.control.follow.service import FollowService
from vibsynth.control.studio.follow import CHANGE_RATE, FollowPanel, follow_limits
from vibsynth.control.studio.server import StudioServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.errors import DeviceError
from vibsynth.settings.models import bounds_of

DEVICES = [
    {"name": "fake mic", "index": 3, "channels": 1, "host_api": "ALSA"},
    {"name": "broken mic", "index": 4, "channels": 1, "host_api": "ALSA"},
]


class BrokenInput(FakeInput):
    def open(self) -> None:
        raise DeviceError("input 'broken mic' cannot be opened: device unavailable")


@pytest.fixture(scope="module")
def bank(basis):
    return build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, levels=9, seed=2))


@pytest.fixture
def rig(bank, basis):
    rig = Rig(bank, basis)
    registry.attach(rig.controller, rig.follower)
    yield rig
    registry.detach(rig.controller, rig.follower)


def studio_for(rig, *, running: bool = True, settings=True):
    opened = []

    def open_source(device):
        source = BrokenInput(1, FS) if device == "broken mic" else FakeInput(1, FS)
        opened.append((device, source))
        return source

    service = FollowService(rig.follower) if running else None
    server = StudioServer(rig.controller, port=0)
    panel = FollowPanel(
        server,
        rig.settings if settings else None,
        [service] if service is not None else [],
        list_inputs=lambda: DEVICES,
        open_source=open_source,
    )
    server.plugins.append(panel)
    server.start()
    return server, panel, opened


@pytest.fixture
def studio(rig):
    server, panel, opened = studio_for(rig)
    server.opened = opened
    yield server
    server.stop()
    panel.stop()


def post(server, body, *, raw: bytes | None = None, origin_header: str | None = "own"):
    headers = {"Content-Type": "application/json"}
    if origin_header is not None:
        headers["Origin"] = origin(server) if origin_header == "own" else origin_header
    status, _, data = http(
        server, "POST", "/api/follow", body=raw if raw is not None else json.dumps(body).encode(), headers=headers
    )
    return status, json.loads(data) if data.startswith(b"{") else data.decode()


def refused(server) -> int:
    return server.gate.refused().get("follow", 0)


def test_the_state_has_the_snapshot_the_whole_trace_and_the_settings_ranges(rig, studio):
    rig.feed(tone(FS, 1.0, 10 ** (-50 / 20)))
    status, _, body = http(studio, "GET", "/api/follow")
    state = json.loads(body)
    assert status == 200 and state["running"] is True and state["hint"] == ""
    assert state["limits"]["gain_db"] == list(map(float, bounds_of("follow.gain_db")))
    assert state["limits"]["range_db"] == list(map(float, bounds_of("follow.range_db")))
    assert state["limits"]["focus"] == ["all", "effects", "bass", "beat"]
    snap = state["snapshot"]
    assert snap["level_db"] == pytest.approx(-50.0, abs=0.5) and snap["gate"] is True
    assert [r["label"] for r in snap["routes"]] == ["ch1", "ch2"]
    trace = state["trace"]["ch1"]
    assert len(trace) == pytest.approx(50, abs=2)
    assert trace[-1][1] == pytest.approx(-50.0, abs=0.5) and trace[-1][2] == pytest.approx(0.75, abs=0.02)


@pytest.mark.parametrize(
    ("body", "getter", "value"),
    [
        ({"gain_db": 6.5}, lambda f: f.gain_db, 6.5),
        ({"gate_db": -45}, lambda f: f.gate_db, -45.0),
        ({"range_db": 30}, lambda f: f.range_db, 30.0),
        ({"focus": "effects"}, lambda f: f.focus, "effects"),
    ],
)
def test_a_change_reaches_the_follower_and_its_trackers(rig, studio, body, getter, value):
    status, answer = post(studio, body)
    assert status == 200, answer
    assert getter(rig.follower) == value
    assert answer["snapshot"][next(iter(body))] == value
    rig.feed(tone(FS, 0.05, 0.01))  # the next step hands the live values to the trackers
    params = rig.follower._routes[0].tracker.params  # noqa: SLF001 - the tracker is what must change
    key = next(iter(body))
    assert getattr(params, key) == value


def test_gain_moves_what_the_output_plays(rig, studio):
    rig.feed(tone(FS, 0.5, 10 ** (-60 / 20)))
    before = rig.plays(0)[0]
    assert post(studio, {"gain_db": 8})[0] == 200
    rig.feed(tone(FS, 0.5, 10 ** (-60 / 20), start=int(0.5 * FS)))
    assert rig.plays(0)[0] - before == pytest.approx(8 / 40, abs=0.02)


def test_follow_off_on_a_channel_hands_it_back_to_the_knobs(rig, studio):
    rig.controller.set_knob("intensity", 0.2, channels=[0], glide_s=0.0)
    rig.feed(tone(FS, 0.5, 10 ** (-50 / 20)))
    assert rig.controller.driver(0) == "follow"
    status, answer = post(studio, {"channel": 1, "on": False})
    assert status == 200 and [r["on"] for r in answer["snapshot"]["routes"]] == [False, True]
    rig.feed(tone(FS, 0.2, 10 ** (-50 / 20)))
    assert rig.controller.driver(0) == "knobs" and rig.plays(0)[0] == pytest.approx(0.2, abs=1e-6)
    assert rig.controller.driver(1) == "follow"
    assert post(studio, {"channel": 1, "on": True})[0] == 200
    rig.feed(tone(FS, 0.2, 10 ** (-50 / 20)))
    assert rig.controller.driver(0) == "follow"


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ({"gain_db": 61}, "outside the allowed range [-60, 60]"),
        ({"gain_db": -1e9}, "outside the allowed range"),
        ({"gate_db": 3}, "outside the allowed range [-200, 0]"),
        ({"range_db": 2}, "outside the allowed range [6, 120]"),
        ({"gain_db": "loud"}, "gain_db must be a finite number"),
        ({"gain_db": True}, "gain_db must be a finite number"),
        ({"gain_db": None}, "gain_db must be a finite number"),
        ({"focus": "voices"}, "focus must be one of all, effects, bass, beat"),
        ({"focus": 3}, "focus must be one of"),
        ({"channel": 3, "on": False}, "channel must be an integer 1..2"),
        ({"channel": 0, "on": False}, "channel must be an integer 1..2"),
        ({"channel": 1, "on": "no"}, "on must be true or false"),
        ({"channel": 1}, "on must be true or false"),
        ({"gain_db": 1, "gate_db": -40}, "one change per request"),
        ({}, "one change per request"),
        ({"gain": 3}, "unknown key"),
        ({"gain_db": 1, "on": True}, "on goes with channel"),
        ({"device": ""}, "device must be an input device's name"),
        ({"device": "x" * 300}, "device must be an input device's name"),
        ([1, 2], "must be a JSON object"),
    ],
)
def test_bad_input_is_refused_with_one_line_counted_and_changes_nothing(rig, studio, body, says):
    before = (rig.follower.gain_db, rig.follower.gate_db, rig.follower.range_db, rig.follower.focus)
    ons = [v.on for v in rig.follower.routes()]
    errors = rig.controller.error_counts.get("studio", 0)
    status, answer = post(studio, body)
    assert status == 400 and says in answer["message"] and "\n" not in answer["message"]
    assert refused(studio) == 1 and rig.controller.error_counts["studio"] == errors + 1
    assert (rig.follower.gain_db, rig.follower.gate_db, rig.follower.range_db, rig.follower.focus) == before
    assert [v.on for v in rig.follower.routes()] == ons


@pytest.mark.parametrize("raw", [b"not json", b"\xff\xfe", b'{"gain_db": NaN}', b'{"gain_db": Infinity}', b"x" * 5000])
def test_malformed_bodies_are_refused_and_counted(rig, studio, raw):
    status, answer = post(studio, None, raw=raw)
    assert status == 400 and refused(studio) == 1 and rig.follower.gain_db == 0.0
    assert isinstance(answer, dict) and answer["message"]


def test_the_gate_refuses_a_foreign_origin_and_no_token(rig, studio):
    status, _ = post(studio, {"gain_db": 3}, origin_header="http://evil.example")
    assert status == 403 and studio.gate.refused()["origin"] == 1
    status, _, _ = http(studio, "POST", "/api/follow", token=None, body=b'{"gain_db": 3}')
    assert status == 403 and studio.gate.refused()["token"] == 1
    assert rig.follower.gain_db == 0.0


def test_a_flood_of_changes_is_refused_over_the_budget_and_counted(rig, studio):
    statuses = [post(studio, {"gain_db": 1.0})[0] for _ in range(int(CHANGE_RATE) * 3)]
    assert 200 in statuses and 429 in statuses
    assert studio.gate.refused()["flood"] == statuses.count(429)


def test_switching_to_a_listed_device_follows_it_and_keeps_the_live_values(rig, studio):
    assert post(studio, {"gain_db": 4})[0] == 200
    old = rig.follower
    status, answer = post(studio, {"device": "fake mic"})
    assert status == 200, answer
    new = registry.follower_of(rig.controller)
    assert new is not old and new.gain_db == 4.0 and answer["snapshot"]["gain_db"] == 4.0
    ((device, source),) = studio.opened
    assert device == "fake mic" and source.state == "open" and rig.source.state == "closed"
    source.write(tone(FS, 0.5, 10 ** (-50 / 20))[:, None])
    new.step()
    assert new.level_db() == pytest.approx(-50.0 + 0.0, abs=1.0)
    new.stop()


def test_an_unlisted_device_or_a_file_path_is_refused_and_the_input_stays(rig, studio):
    for device in ("/etc/passwd", "music.wav", "fake"):
        status, answer = post(studio, {"device": device})
        assert status == 400 and "no input device named" in answer["message"] and "fake mic" in answer["message"]
    assert registry.follower_of(rig.controller) is rig.follower and rig.source.state == "open"
    assert studio.opened == [] and refused(studio) == 3


def test_a_device_that_cannot_open_is_reported_and_the_previous_input_reopened(rig, studio):
    status, answer = post(studio, {"device": "broken mic"})
    assert status == 400 and "cannot be opened" in answer["message"]
    assert registry.follower_of(rig.controller) is rig.follower and rig.source.state == "open"
    state = json.loads(http(studio, "GET", "/api/follow")[2])
    assert "cannot be opened" in state["error"] and state["running"] is True
    rig.follower.stop()


def test_without_follow_the_panel_says_how_to_start_and_can_start_one(rig):
    registry.detach(rig.controller, rig.follower)
    server, panel, opened = studio_for(rig, running=False)
    try:
        state = json.loads(http(server, "GET", "/api/follow")[2])
        assert state["running"] is False and "serve with --follow" in state["hint"] and state["can_start"] is True
        status, answer = post(server, {"gain_db": 3})
        assert status == 409 and "--follow" in answer["message"]
        status, answer = post(server, {"device": "fake mic"})
        assert status == 200 and answer["running"] is True
        assert registry.follower_of(rig.controller) is not None and panel.started is not None
    finally:
        server.stop()
        panel.stop()
    assert registry.follower_of(rig.controller) is None  # the studio stops what it started


def test_a_studio_without_settings_cannot_switch_inputs(rig):
    server, panel, _ = studio_for(rig, settings=False)
    try:
        registry.detach(rig.controller, rig.follower)
        state = json.loads(http(server, "GET", "/api/follow")[2])
        assert state["can_start"] is False and "pick an input" not in state["hint"] and "--follow" in state["hint"]
        registry.attach(rig.controller, rig.follower)
        status, answer = post(server, {"device": "fake mic"})
        assert status == 409 and "cannot start or switch" in answer["message"]
        assert registry.follower_of(rig.controller) is rig.follower
    finally:
        server.stop()


def test_devices_lists_the_inputs_and_the_current_one(rig, studio):
    data = json.loads(http(studio, "GET", "/api/follow/devices")[2])
    assert [d["name"] for d in data["devices"]] == ["fake mic", "broken mic"] and data["current"] == "fake input"


def test_open_pages_get_the_trace_pushed(rig, studio):
    async def scenario():
        import aiohttp

        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            rig.feed(tone(FS, 0.5, 10 ** (-50 / 20)))

            def settled(m: dict) -> bool:  # pushes come every 0.1 s: the first may catch the level's attack
                trace = m.get("trace", {}).get("ch1") if m.get("type") == "follow" else None
                return bool(trace) and trace[-1][1] > -50.5

            message = await receive_until(ws, settled)
            await ws.close()
            return message

    message = run(scenario())
    points = np.array([p[1] for p in message["trace"]["ch1"]])
    assert message["full"] is False and points[-1] == pytest.approx(-50.0, abs=0.5)
    assert np.all(np.abs(points[len(points) // 2 :] + 50.0) < 1.0)  # the tone's level, held


def test_the_limits_are_the_typed_settings_ranges():
    limits = follow_limits()
    for key in ("gain_db", "gate_db", "range_db"):
        assert tuple(limits[key]) == tuple(float(v) for v in bounds_of(f"follow.{key}"))
