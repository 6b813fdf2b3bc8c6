"""The studio's presets panel: list, save (validated like files, errors per field), edit, delete, hot reload."""

from __future__ import annotations

import json

import aiohttp
import numpy as np
import pytest

from tests.control.studio.helpers import connect, get_json, http, receive_until, run
from vibsynth.control.studio.presets import form_schema
from vibsynth.settings.presets import load_preset
from vibsynth.settings.reload import PresetWatcher


def post(studio, path: str, body) -> tuple[int, dict]:
    raw = body if isinstance(body, bytes) else json.dumps(body).encode()
    status, _, data = http(studio, "POST", path, body=raw, headers={"Content-Type": "application/json"})
    return status, json.loads(data)


def delete(studio, name: str) -> tuple[int, dict]:
    status, _, data = http(studio, "DELETE", f"/api/presets/{name}")
    return status, json.loads(data) if data.startswith(b"{") else {"text": data.decode()}


def test_the_listing_has_shipped_presets_and_the_form_schema(studio, library):
    listing = get_json(studio, "/api/presets")
    names = [p["name"] for p in listing["presets"]]
    assert names == library.names() and "brick" in names
    brick = next(p for p in listing["presets"] if p["name"] == "brick")
    assert brick["origin"] == "shipped" and brick["read_only"] is True
    assert brick["intensity"] == library.get("brick").intensity
    fields = {f["key"]: f for f in listing["schema"]}
    assert list(fields) == ["name", "description", "intensity", "balance", "glide_ms", "program", "tags"]
    assert (fields["intensity"]["minimum"], fields["intensity"]["maximum"]) == (0, 1)
    assert (fields["balance"]["minimum"], fields["balance"]["maximum"]) == (-4.0, 4.0)
    assert (fields["glide_ms"]["minimum"], fields["glide_ms"]["maximum"]) == (0, 10000.0)
    assert fields["program"]["type"] == "integer" and fields["program"]["maximum"] == 127
    assert fields["name"]["required"] and fields["intensity"]["required"] and not fields["tags"]["required"]
    assert form_schema() == listing["schema"]


def test_save_edit_and_delete_a_user_preset(studio, library, user_dir):
    form = {"name": "my-silk", "intensity": 0.4, "balance": -1.25, "glide_ms": 80, "tags": ["soft", "mine"]}
    status, result = post(studio, "/api/presets", {**form, "like": "brick", "description": "smooth"})
    assert status == 200, result
    path = user_dir / "my-silk.yaml"
    assert result["path"] == str(path)
    saved = load_preset(path)
    assert (saved.intensity, saved.balance, saved.glide_ms, saved.tags) == (0.4, -1.25, 80.0, ("soft", "mine"))
    assert saved.description == "smooth"
    assert saved.provenance["edited_from"] == "brick" and "studio" in saved.provenance["created_by"]
    assert library.get("my-silk").origin == "user"
    # saving the same name again without overwrite is refused (409) and changes nothing
    status, result = post(studio, "/api/presets", {**form, "intensity": 0.9})
    assert status == 409 and result["exists"] is True and "save again to replace" in result["message"]
    assert load_preset(path).intensity == 0.4
    # the edit replaces it when told
    status, result = post(studio, "/api/presets", {**form, "intensity": 0.9, "overwrite": True, "like": "my-silk"})
    assert status == 200
    assert load_preset(path).intensity == 0.9
    status, result = delete(studio, "my-silk")
    assert status == 200 and result["deleted"] == "my-silk"
    assert not path.exists() and "my-silk" not in library


@pytest.mark.parametrize(
    ("form", "key", "says"),
    [
        ({"intensity": 1.5, "balance": 0}, "intensity", "outside the allowed range [0, 1]"),
        ({"intensity": 0.5, "balance": "dark"}, "balance", "must be a number"),
        ({"intensity": 0.5, "balance": 9}, "balance", "outside the allowed range [-4, 4]"),
        ({"intensity": 0.5, "balance": 0, "glide_ms": -5}, "glide_ms", "outside the allowed range"),
        ({"intensity": 0.5, "balance": 0, "program": 1.5}, "program", "integer"),
        ({"intensity": 0.5, "balance": 0, "tags": ["ok", "no/slash"]}, "tags[1]", "must be 1-32 letters"),
        ({"intensity": 0.5, "balance": 0, "tags": "rough"}, "tags", "must be a list"),
        ({"balance": 0}, "intensity", "missing key 'intensity'"),
        ({"intensity": 0.5, "balance": 0, "colour": "red"}, "colour", "unknown key 'colour'"),
    ],
)
def test_wrong_fields_are_named_and_nothing_is_written(studio, user_dir, form, key, says):
    status, result = post(studio, "/api/presets", {"name": "bad-one", **form})
    assert status == 400, result
    problems = {p["key"]: p["message"] for p in result["problems"]}
    assert key in problems and says in problems[key], problems
    assert says in result["message"]
    assert not (user_dir / "bad-one.yaml").exists()


def test_save_as_with_a_channel_takes_what_it_plays_for_the_fields_left_out(studio, controller, user_dir):
    """The page of a fresh studio sends only a name and its channel: the preset is the sound that plays."""
    rng = np.random.default_rng(26)
    intensity, balance = (round(float(v), 6) for v in (rng.uniform(0.1, 0.9), rng.uniform(-3.0, 3.0)))
    controller.set_texture(intensity, balance, channels=[1])  # channel 2 (1-based)
    controller.set_texture(0.05, -0.5, channels=[0])
    status, result = post(studio, "/api/presets", {"name": "heard", "channel": 2, "like": None, "overwrite": False})
    assert status == 200, result
    saved = load_preset(user_dir / "heard.yaml")
    assert (saved.intensity, saved.balance) == (intensity, balance)
    assert saved.provenance["from_knobs"] == {"channel": 2, "keys": ["intensity", "balance"]}
    # a field the form gives wins; only the one left out (or empty) comes from the knobs
    status, result = post(studio, "/api/presets", {"name": "half", "channel": 1, "intensity": 0.75, "balance": ""})
    assert status == 200, result
    saved = load_preset(user_dir / "half.yaml")
    assert (saved.intensity, saved.balance) == (0.75, -0.5)
    assert saved.provenance["from_knobs"] == {"channel": 1, "keys": ["balance"]}
    # editing it with both fields typed: nothing comes from the knobs, nor is said to
    form = {"name": "half", "channel": 1, "intensity": 0.2, "balance": 1.0, "like": "half", "overwrite": True}
    assert post(studio, "/api/presets", form)[0] == 200
    saved = load_preset(user_dir / "half.yaml")
    assert (saved.intensity, saved.balance) == (0.2, 1.0) and "from_knobs" not in saved.provenance


@pytest.mark.parametrize("channel", [0, 3, -1, "1", 1.0, True, [1], {"c": 1}, pytest.param("x" * 5000, id="long")])
def test_a_channel_that_is_not_one_of_the_engines_is_refused(studio, controller, user_dir, channel):
    status, result = post(studio, "/api/presets", {"name": "nowhere", "channel": channel})
    assert status == 400, result
    assert result["problems"] == [{"key": "channel", "message": result["problems"][0]["message"]}]
    assert "channel must be an integer 1..2" in result["message"] and len(result["message"]) <= 200
    assert not (user_dir / "nowhere.yaml").exists()
    assert controller.error_counts["studio"] == 1


@pytest.mark.parametrize("name", ["../x", "a/b", "..", ".hidden", "", "x" * 65, "semi;colon", 7, None])
def test_names_that_are_not_plain_file_names_are_refused(studio, user_dir, tmp_path, name):
    status, result = post(studio, "/api/presets", {"name": name, "intensity": 0.5, "balance": 0})
    assert status == 400
    assert result["problems"] == [{"key": "name", "message": result["problems"][0]["message"]}]
    assert "letters, digits" in result["message"]
    assert not (tmp_path / "x.yaml").exists() and not (user_dir.parent / "x.yaml").exists()
    assert not user_dir.exists() or list(user_dir.iterdir()) == []


@pytest.mark.parametrize("path", ["..%2Fx", "a%2Fb", "..", "%2E%2E%2Fbrick"])
def test_deleting_outside_the_user_folder_is_refused(studio, user_dir, path):
    (user_dir.parent / "x.yaml").write_text("intensity: 0.5\nbalance: 0\n")
    status, result = delete(studio, path)
    assert status in (400, 404)
    assert (user_dir.parent / "x.yaml").exists()


def test_shipped_presets_are_read_only(studio, library):
    status, result = delete(studio, "brick")
    assert status == 409 and "read-only" in result["message"]
    assert "brick" in library
    status, result = delete(studio, "no-such-preset")
    assert status == 404 and "unknown preset" in result["message"]


def test_a_user_preset_may_override_a_shipped_one_and_deleting_it_brings_it_back(studio, library):
    status, result = post(studio, "/api/presets", {"name": "brick", "intensity": 0.1, "balance": 0.0})
    assert status == 200 and "overrides the shipped preset" in result["note"]
    assert library.get("brick").intensity == 0.1
    status, result = delete(studio, "brick")
    assert status == 200 and "shipped preset of that name is used again" in result["note"]
    assert library.get("brick").origin == "shipped"


def test_malformed_and_oversize_bodies(studio):
    assert post(studio, "/api/presets", b"{not json")[0] == 400
    assert post(studio, "/api/presets", b"[1, 2]")[0] == 400
    assert post(studio, "/api/presets", {"name": "a", "intensity": 0.5, "balance": 0, "overwrite": "yes"})[0] == 400
    big = json.dumps({"name": "a", "description": "x" * (2 << 20)}).encode()
    status, _, _ = http(studio, "POST", "/api/presets", body=big, headers={"Content-Type": "application/json"})
    assert status == 413
    status, result = post(
        studio, "/api/presets", {"name": "long", "intensity": 0.5, "balance": 0, "description": "x" * 5000}
    )
    assert status == 400 and result["problems"][0]["key"] == "description"


def test_hot_reloaded_changes_reach_the_page(studio, library, user_dir):
    """A file written by hand (the watcher reloads it) appears on the open page."""
    watcher = PresetWatcher(library, on_change=lambda name: None, interval_s=0.05)

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            first = await receive_until(ws, lambda m: m.get("type") == "presets")
            assert "by-hand" not in [p["name"] for p in first["presets"]]
            user_dir.mkdir(parents=True, exist_ok=True)
            (user_dir / "by-hand.yaml").write_text("version: 1\nintensity: 0.25\nbalance: 1.5\ntags: [hand]\n")
            watcher.start()
            try:
                pushed = await receive_until(
                    ws, lambda m: m.get("type") == "presets" and "by-hand" in [p["name"] for p in m["presets"]]
                )
            finally:
                watcher.stop()
            await ws.close()
            return pushed

    pushed = run(scenario())
    entry = next(p for p in pushed["presets"] if p["name"] == "by-hand")
    assert (entry["intensity"], entry["balance"], entry["tags"], entry["origin"]) == (0.25, 1.5, ["hand"], "user")


def test_without_a_library_the_panel_says_so(controller):
    from vibsynth.control.studio.panels import install_panels
    from vibsynth.control.studio.server import StudioServer

    server = StudioServer(controller, port=0)
    install_panels(server)
    server.start()
    try:
        assert get_json(server, "/api/presets")["available"] is False
        status, result = post(server, "/api/presets", {"name": "a", "intensity": 0.5, "balance": 0})
        assert status == 409 and "no preset library" in result["message"]
    finally:
        server.stop()
