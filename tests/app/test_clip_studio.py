"""The studio's clip lane routes: list, get, save, import, play/stop/playing through the player; every refusal."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.control.osc.fakes import make_controller
from tests.control.studio.helpers import http, origin
from vibsynth.app.clips.studio import StudioClips, studio_extension
from vibsynth.app.studio_tabs import studio_extensions
from vibsynth.control.clips import attach
from vibsynth.control.studio.server import StudioServer
from vibsynth.settings.clips import load_clip, parse_clip
from vibsynth.settings.config import load_config

GOOD = {
    "duration_ms": 500,
    "loop": {"start_ms": 0, "end_ms": 500},
    "keyframes": [
        {"t_ms": 0, "intensity": 0.2, "balance": -1},
        {"t_ms": 250, "intensity": 0.9, "balance": 1, "interp": "smooth"},
        {"t_ms": 500, "intensity": 0.0, "balance": 0},
    ],
    "transients": [{"t_ms": 100, "intensity": 1, "balance": 2, "decay_ms": 30}],
}


@dataclass
class Position:
    clip_ms: float
    loops_left: int


@dataclass
class Now:
    name: str
    position: Position
    started: bool = True


class FakePlayer:
    """What the lane needs of the service's clip player: play, stop, playing and its resolver."""

    def __init__(self, resolve) -> None:
        self.resolve = resolve
        self.calls: list[tuple] = []
        self.current: dict[int, object] = {}

    def play(self, name, *, channels=None, gain=1.0, rate=1.0, loops=1, at_frame=None, source="api"):
        clip = self.resolve(name)
        self.calls.append(("play", name, tuple(channels), loops, source))
        for c in channels:
            self.current[c] = clip

    def stop(self, *, channels=None, release_s=None, at_frame=None, source="api"):
        self.calls.append(("stop", tuple(channels), source))
        return sum(1 for c in channels if self.current.pop(c, None) is not None)

    def playing(self, channel):
        clip = self.current.get(channel)
        return None if clip is None else Now(clip.name, Position(123.0, -1))


@pytest.fixture
def user_dir(tmp_path):
    return tmp_path / "clips"


@pytest.fixture
def controller():
    return make_controller(2)


@pytest.fixture
def lane(controller, user_dir):
    config = load_config(env={}, user_file=False, overrides={"clips.user_dir": str(user_dir)})
    server = StudioServer(controller, port=0, extensions=studio_extensions(config.settings, controller, None))
    server.start()
    yield server
    server.stop()


def call(server, method, path, body=None, *, raw: bytes | None = None):
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    headers = {"Origin": origin(server), "Content-Type": "application/json"}
    status, _, out = http(server, method, path, headers=headers, body=data)
    return status, json.loads(out) if out else None


def test_the_lane_is_a_studio_extension_with_its_script(lane):
    status, state = call(lane, "GET", "/api/state")
    assert {"name": "clips", "title": "Clips", "script": "/ext/clips/tab.js"} in state["extensions"]
    status, headers, body = http(lane, "GET", "/ext/clips/tab.js")
    assert status == 200 and b"export async function mount(panel, studio)" in body
    for testid in ("clip-item", "clip-play", "clip-stop", "clip-canvas", "clip-save", "clip-import-file", "clip-error"):
        assert f'"data-testid": "{testid}"'.encode() in body or f'data-testid=\\"{testid}'.encode() in body


def test_routes_need_the_token_and_the_origin(lane):
    status, _, _ = http(lane, "GET", "/ext/clips/list", token=None)
    assert status == 403
    status, _, _ = http(lane, "PUT", "/ext/clips/clip/x", body=b"{}", headers={"Origin": "http://evil.example"})
    assert status == 403


def test_list_and_get(lane, user_dir):
    status, data = call(lane, "GET", "/ext/clips/list")
    assert status == 200 and [c["name"] for c in data["clips"]] == [
        "gravel-steps",
        "heartbeat",
        "impact",
        "rain",
        "zipper",
    ]
    heart = next(c for c in data["clips"] if c["name"] == "heartbeat")
    assert heart == {
        "name": "heartbeat",
        "origin": "shipped",
        "duration_ms": 1000.0,
        "keyframes": 7,
        "transients": 2,
        "loop": [0.0, 1000.0],
        "tags": ["body", "heartbeat", "loop"],
    }
    assert data["playing"] is False and data["user_dir"] == str(user_dir)
    status, data = call(lane, "GET", "/ext/clips/clip/impact")
    assert status == 200 and data["origin"] == "shipped" and data["clip"]["transients"][0]["decay_ms"] == 45
    status, data = call(lane, "GET", "/ext/clips/clip/impakt")
    assert status == 404 and data["message"].startswith("unknown clip 'impakt'; did you mean impact?")
    status, data = call(lane, "GET", "/ext/clips/clip/..x")
    assert status == 400 and "not a clip name" in data["message"]


def test_save_writes_the_user_folder_and_a_bad_clip_changes_nothing(lane, user_dir):
    status, data = call(lane, "PUT", "/ext/clips/clip/mine", GOOD)
    assert status == 200 and data["saved"] == str(user_dir / "mine.yaml")
    saved = load_clip(user_dir / "mine.yaml")
    assert saved.keyframes[1].interp == "smooth" and saved.transients[0].decay_ms == 30 and saved.loop == (0.0, 500.0)
    before = (user_dir / "mine.yaml").read_bytes()
    bad = {**GOOD, "keyframes": [GOOD["keyframes"][0], {**GOOD["keyframes"][1], "t_ms": 0}]}
    status, data = call(lane, "PUT", "/ext/clips/clip/mine", bad)
    assert status == 400 and data["message"].startswith(
        "clip 'mine': keyframes[1].t_ms = 0: keyframe times must strictly"
    )
    assert data["problems"][0]["key"] == "keyframes[1].t_ms"
    status, data = call(lane, "PUT", "/ext/clips/clip/mine", raw=b'{"duration_ms": NaN}')
    assert status == 400 and "NaN is not a number" in data["message"]
    assert (user_dir / "mine.yaml").read_bytes() == before
    status, data = call(lane, "GET", "/ext/clips/list")
    assert {"name": "mine", "origin": "user"}.items() <= next(c for c in data["clips"] if c["name"] == "mine").items()


def test_import_returns_an_unsaved_clip_and_refuses_bad_files(lane, user_dir):
    ahap = {
        "Version": 1,
        "Pattern": [
            {
                "Event": {
                    "Time": 0.0,
                    "EventType": "HapticContinuous",
                    "EventDuration": 0.2,
                    "Foo": 1,
                    "EventParameters": [
                        {"ParameterID": "HapticIntensity", "ParameterValue": 0.5},
                        {"ParameterID": "HapticSharpness", "ParameterValue": 1.0},
                    ],
                }
            }
        ],
    }
    status, data = call(lane, "POST", "/ext/clips/import?file=My%20Buzz.ahap", raw=json.dumps(ahap).encode())
    assert (
        status == 200 and data["clip"]["name"] == "My-Buzz" and data["ignored"] == ["unknown field Pattern[].Event.Foo"]
    )
    assert data["clip"]["keyframes"][0] == {"t_ms": 0, "intensity": 0.5, "balance": 3.5, "interp": "hold"}
    assert not user_dir.exists()  # not saved
    status, data = call(lane, "POST", "/ext/clips/import?file=x.ahap", raw=b'{"Pattern": [{"Event": {"Time": 0.0, "Ev')
    assert status == 400 and data["message"].startswith("x.ahap:1:") and "truncated" in data["message"]
    status, data = call(lane, "POST", "/ext/clips/import?file=x.wav", raw=b"RIFF")
    assert status == 400 and "expected an AHAP (.ahap) or Meta Haptics Studio (.haptic) file" in data["message"]
    status, data = call(lane, "POST", "/ext/clips/import?file=x.haptic", raw=b"\xff\xfe")
    assert status == 400 and data["message"] == "x.haptic: not a UTF-8 text file"
    status, _, _ = http(
        lane, "POST", "/ext/clips/import?file=x.ahap", headers={"Origin": origin(lane)}, body=b" " * (2 << 20)
    )
    assert status == 413


def test_play_stop_and_playing_go_through_the_player(lane, controller):
    status, data = call(lane, "POST", "/ext/clips/play", {"name": "impact", "channel": 1})
    assert status == 400 and data["message"] == "clips are not available (no clip player is running)"
    library_calls = []

    def resolve(name):
        library_calls.append(name)
        return parse_clip("duration_ms: 10\nkeyframes: [{t_ms: 0, intensity: 0, balance: 0}]\n", name=name)

    player = FakePlayer(resolve)
    attach(controller, player)
    status, data = call(lane, "POST", "/ext/clips/play", {"name": "draft", "channel": 2, "loop": True, "clip": GOOD})
    assert status == 200 and data == {"playing": "draft", "channel": 2, "loop": True}
    assert player.calls == [("play", "studio:draft", (1,), 0, "studio")]
    assert isinstance(player.resolve, StudioClips) and player.current[1].keyframes[1].interp == "smooth"
    assert player.resolve("other").name == "other" and library_calls == [
        "other"
    ]  # the player's own clips still resolve
    status, data = call(lane, "GET", "/ext/clips/playing?channel=2")
    assert data == {"channel": 2, "playing": {"name": "draft", "position_ms": 123.0, "loops_left": -1, "started": True}}
    status, data = call(lane, "POST", "/ext/clips/play", {"name": "heartbeat", "channel": 1})  # the saved clip
    assert status == 200 and player.calls[-1] == ("play", "studio:heartbeat", (0,), 1, "studio")
    assert player.current[0].transients[1].t_ms == 300
    status, data = call(lane, "POST", "/ext/clips/stop", {"channel": 2})
    assert status == 200 and data == {"stopped": 1, "channel": 2} and player.calls[-1] == ("stop", (1,), "studio")
    status, data = call(lane, "GET", "/ext/clips/playing?channel=2")
    assert data == {"channel": 2, "playing": None}


@pytest.mark.parametrize(
    "body, message",
    [
        ({"name": "x", "channel": 3}, "channel = 3: no such channel (allowed: 1..2)"),
        ({"name": "x", "channel": True}, "channel = True: no such channel"),
        ({"name": "x/y", "channel": 1}, "clip name 'x/y': not a clip name"),
        ({"name": "x", "channel": 1, "loop": "yes"}, "loop = 'yes': must be true or false"),
        ({"name": "x", "channel": 1, "clip": {**GOOD, "duration_ms": -1}}, "clip 'x': duration_ms = -1: outside"),
        ({"name": "nosuch", "channel": 1}, "unknown clip 'nosuch'"),
        ([1, 2], "play: expected {name, channel, loop, clip}"),
    ],
)
def test_play_refusals_name_the_problem_and_play_nothing(lane, controller, body, message):
    player = FakePlayer(lambda name: None)
    attach(controller, player)
    status, data = call(lane, "POST", "/ext/clips/play", body)
    assert status in (400, 404) and data["message"].startswith(message) and player.calls == []


def test_the_extension_uses_the_configured_folder(tmp_path, controller):
    config = load_config(env={}, user_file=False, overrides={"clips.user_dir": str(tmp_path / "c")})
    extension = studio_extension(config.settings, controller, None)
    extension.check()
    assert extension.name == "clips" and Path(extension.script).name == "clip_tab.js"
