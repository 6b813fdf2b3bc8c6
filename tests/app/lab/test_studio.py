"""The Lab tab's routes in a real studio server over a real engine (rendered offline)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from tests.control.studio.helpers import connect, http, receive_until, run
from vibsynth.app.lab.studio import LabService
from vibsynth.control.studio.extension import StudioExtension
from vibsynth.control.studio.server import StudioServer


@pytest.fixture
def lab(tmp_path, controller):
    from vibsynth.settings.config import load_config
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    config = load_config(
        None, overrides={"lab.folder": str(tmp_path / "sessions"), "lab.stimulus_s": 0.5}, user_file=False
    )
    service = LabService(
        config.settings.lab, config.settings.knobs, controller, PresetLibrary(shipped_presets_dir(), None)
    )
    ext = StudioExtension(name="lab", title="Lab", script=service_script(), add_routes=service.add_routes)
    server = StudioServer(controller, port=0, extensions=[ext])
    server.start()
    yield server, service
    service.runner.close()
    server.stop()


def service_script():
    from vibsynth.app.lab.studio import STATIC

    return STATIC / "lab_tab.js"


def post(server, path, body):
    status, _, data = http(
        server,
        "POST",
        f"/ext/lab/{path}",
        body=json.dumps(body).encode(),
        headers={"Content-Type": "application/json", "Origin": f"http://127.0.0.1:{server.port}"},
    )
    return status, json.loads(data)


def get(server, path):
    status, _, data = http(server, "GET", f"/ext/lab/{path}")
    return status, json.loads(data)


START = {
    "protocol": "dissimilarity",
    "stimuli": "renders",
    "folder": "",
    "participant": "p01",
    "seed": "12",
    "familiarisation": 0,
    "channel": 0,
}


def test_setup_offers_protocols_sets_and_the_papers_defaults(lab):
    server, _ = lab
    status, data = get(server, "setup")
    assert status == 200
    assert data["protocols"] == ["intensity", "dissimilarity", "resynthesis"]
    assert [s["value"] for s in data["sets"]] == ["presets", "renders", "sines"]
    assert data["defaults"]["familiarisation_pairs"] == 30 and data["defaults"]["gap_s"] == 0.5
    assert data["defaults"]["gain_min"] == 0.2 and data["defaults"]["gain_max"] == 5.0
    assert data["sessions"] == [] and data["state"]["status"] == "idle"
    status, _, body = http(server, "GET", "/ext/lab/lab.css")
    assert status == 200 and b".lab" in body


def test_a_session_runs_through_the_routes_and_pages_are_told(lab, controller):
    server, service = lab

    async def scenario():
        import aiohttp

        async with aiohttp.ClientSession() as session:
            ws = await connect(session, server)
            await receive_until(ws, lambda m: m.get("type") == "hello")
            status, state = post(server, "start", START)
            assert status == 200, state
            pushed = await receive_until(ws, lambda m: m.get("type") == "ext" and m["data"].get("status") == "running")
            await ws.close()
            return state, pushed["data"]

    state, pushed = run(scenario())
    assert state["status"] == "running" and state["phase"] == "test" and state["progress"] == [1, 36]
    assert pushed["progress"] == [1, 36]
    assert controller.get("mute", 0) is True
    names = list(service.runner.session.stimuli())
    for k in range(3):
        status, state = post(server, "answer", {"value": 0.25 * k})
        assert status == 200 and state["progress"] == [k + 2, 36]
        assert not any(n in json.dumps(state) for n in names)
    assert post(server, "play", {})[0] == 200
    assert post(server, "pause", {})[1]["status"] == "paused"
    assert post(server, "answer", {"value": 0.5}) == (400, {"message": "the run is paused: resume it first"})
    assert post(server, "resume", {})[1]["status"] == "running"
    folder = service.runner.session.folder
    assert post(server, "stop", {})[1]["status"] == "idle"
    with open(folder / "trials.csv", newline="") as handle:
        assert [r["rating"] for r in csv.DictReader(handle)] == ["0", "0.25", "0.5"]
    # it is listed as resumable, and resumes at trial 4
    _, data = get(server, "setup")
    assert [(s["participant"], s["done"], s["complete"]) for s in data["sessions"]] == [("p01", 3, False)]
    status, state = post(server, "open", {"folder": str(folder)})
    assert status == 200 and state["progress"] == [4, 36]
    post(server, "stop", {})


@pytest.mark.parametrize(
    "change, message",
    [
        ({"participant": "../evil"}, "participant id '../evil' is not allowed"),
        ({"participant": "a/b"}, "participant id 'a/b' is not allowed"),
        ({"seed": "-1"}, "seed must be an integer"),
        ({"seed": "9" * 30}, "seed must be an integer"),
        ({"seed": True}, "seed: expected"),
        ({"protocol": "abx"}, "unknown protocol 'abx'"),
        ({"stimuli": "renders:1"}, "the count must be 2..60"),
        ({"folder": "/nonexistent/stimuli"}, "/nonexistent/stimuli: no such folder"),
        ({"familiarisation": -3}, "familiarisation_pairs must be in"),
        ({"familiarisation": "30"}, "familiarisation: expected int"),
        ({"channel": 9}, "channel must be 0 (all) or 1..2"),
        ({"participant": "x" * 5000}, "participant: longer than 4096 characters"),
        ({"stimuli": "sines:10,20"}, "give 8-12 different frequencies in 10-1000 Hz"),
        ({"protocol": "intensity", "stimuli": "sines", "reference": "sine:5000"}, "give sine:F with F in 10-1000 Hz"),
        ({"protocol": "intensity", "stimuli": "sines", "reference": 250}, "reference: expected str"),
        ({"stimuli": "sines", "protocol": "dissimilarity"}, "use the intensity protocol"),
    ],
)
def test_bad_set_up_is_refused_in_one_line_and_writes_nothing(lab, tmp_path, change, message):
    server, service = lab
    status, data = post(server, "start", {**START, **change})
    assert status == 400 and message in data["message"] and "\n" not in data["message"]
    assert not (tmp_path / "sessions").exists() or list((tmp_path / "sessions").iterdir()) == []
    assert service.errors == 1


def test_folder_with_no_or_broken_wavs_is_refused(lab, tmp_path):
    server, _ = lab
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "no WAV files" in post(server, "start", {**START, "folder": str(empty)})[1]["message"]
    (empty / "x.wav").write_bytes(b"RIFF....WAVEjunk")
    assert "x.wav" in post(server, "start", {**START, "folder": str(empty)})[1]["message"]


def test_bodies_and_requests_out_of_place_are_refused(lab):
    server, _ = lab
    status, _, body = http(
        server,
        "POST",
        "/ext/lab/start",
        body=b"{not json",
        headers={"Content-Type": "application/json", "Origin": f"http://127.0.0.1:{server.port}"},
    )
    assert status == 400 and b"not JSON" in body
    assert post(server, "answer", {"value": 0.5})[1]["message"] == "no trial is shown: start or resume a session"
    assert post(server, "open", {"folder": "/etc"})[1]["message"].startswith("/etc: not a session of")
    assert post(server, "analyze", {"folders": ["/etc"]})[0] == 400
    assert post(server, "answer", {"ratings": {"../1": 1}})[0] == 400
    status, _, _ = http(server, "POST", "/ext/lab/start", body=b"{}", headers={"Origin": "http://evil.example"})
    assert status == 403  # the studio's Origin check covers the lab's routes
    status, _, _ = http(server, "GET", "/ext/lab/setup", token="wrong")
    assert status == 403


def test_results_after_a_session_and_the_equalised_set(lab, tmp_path):
    server, service = lab
    status, state = post(server, "start", {**START, "protocol": "intensity", "stimuli": "presets:cork,wood,brick"})
    assert status == 200 and state["progress"] == [1, 3] and state["gain_range"] == [0.2, 5.0]
    assert np.isclose(10 ** state["start"], service.runner.session.plan.test[0].start_gain)
    for _ in range(3):
        state = post(server, "answer", {"value": 1.2})[1]
    assert state["status"] == "done"
    folder = state["folder"]
    status, result = post(server, "analyze", {"folders": [folder]})
    assert status == 200 and result["protocol"] == "intensity" and result["mean_gain"] == pytest.approx([1.2] * 3)
    status, stored = post(server, "equalise", {"folders": [folder]})
    assert status == 200 and stored["stimuli"] == 3
    _, data = get(server, "setup")
    assert stored["folder"] in [s["value"] for s in data["sets"]]


def test_an_iso_intensity_session_on_sines_and_its_curve(lab, controller):
    """Sines matched to a 200 Hz reference sine: the slider spans +-24 dB, the results hold the curve."""
    server, service = lab
    status, state = post(
        server, "start", {**START, "protocol": "intensity", "stimuli": "sines", "reference": "sine:200"}
    )
    assert status == 200, state
    assert state["gain_range"] == [1 / 16, 16.0] and state["progress"] == [1, 10]
    session = service.runner.session
    folder = session.folder
    assert session.meta["set"]["reference_hz"] == 200.0
    truth = {}
    for _ in range(10):
        sid = session.next_trial.stimuli[0]
        f = session.params()[sid]["frequency_hz"]
        truth[f] = 6.0 * np.log2(f / 200.0) ** 2 / 10  # a U, 0 dB at the reference
        status, state = post(server, "answer", {"value": float(10 ** (truth[f] / 20))})
        assert status == 200, state
    assert state["status"] == "done"
    status, result = post(server, "analyze", {"folders": [str(folder)]})
    assert status == 200, result
    iso = result["iso"]
    assert iso["reference_hz"] == 200.0 and iso["frequency_hz"] == sorted(truth)
    assert iso["mean_db"] == pytest.approx([truth[f] for f in sorted(truth)], abs=0.01)


def test_a_staircase_session_is_answered_stronger_or_weaker(lab):
    server, service = lab
    body = {**START, "protocol": "intensity", "stimuli": "sines", "method": "staircase"}
    status, state = post(server, "start", body)
    assert status == 200, state
    assert state["method"] == "staircase" and state["progress"] == [1, 160]
    session = service.runner.session
    first = session.next_trial
    assert service.runner._gain == pytest.approx(first.start_gain)  # the staircase's first level
    assert post(server, "gain", {"gain": 2.0}) == (
        400,
        {"message": "the staircase sets the level: answer stronger or weaker"},
    )
    assert post(server, "play", {"gain": 2.0})[0] == 400 and post(server, "play", {})[0] == 200
    assert post(server, "answer", {"judgement": "louder"})[0] == 400
    status, state = post(server, "answer", {"judgement": "stronger"})
    assert status == 200 and state["progress"] == [2, 160]
    row = session.rows[0]
    assert row["judgement"] == "stronger" and float(row["gain"]) == pytest.approx(first.start_gain, rel=1e-5)
    post(server, "stop", {})
