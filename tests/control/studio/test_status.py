"""The studio's status panel: the numbers of OSC /status, MIDI counters, the studio's own refusals."""

from __future__ import annotations

from collections import Counter

import aiohttp

from tests.control.osc.fakes import make_controller
from tests.control.studio.helpers import connect, get_json, http, receive_until, run
from vibsynth.control.osc.server import OscServer
from vibsynth.control.studio.panels import install_panels
from vibsynth.control.studio.server import StudioServer
from vibsynth.control.studio.status import midi_learn, status_sources, studio_status


class FakeOutput:
    name = "sounddevice"
    state = "device lost"
    state_reason = "JACK server shut down"

    def describe(self) -> str:
        return "JACK Audio Connection Kit: system (2 ch), 48000 Hz, block 128"


class FakeMidi:
    name = "midi"

    def __init__(self) -> None:
        self.mapper = type("Mapper", (), {"counts": Counter({"cc": 12, "note_on": 3}), "learning": "balance"})()

    def describe(self) -> str:
        return "MIDI on input 'Launch Control' (rtmidi), mode gate, learning balance"


def test_status_shows_the_osc_reply_and_midi_counters():
    controller = make_controller(2)
    controller.output = FakeOutput()
    controller.set_knob("intensity", 0.3, channels=[1])
    osc = OscServer(controller, port=0)
    controller.tap.error("/vibsynth/intensity: 1.5 is outside the allowed range [0, 1]")
    status = studio_status(
        controller, sources=status_sources([osc, FakeMidi()]), servers=[osc, FakeMidi()], refused={"token": 2}, pages=1
    )
    timed = ("uptime", "last_error_age")
    reply = dict(osc.handler.status_pairs())
    assert {k: v for k, v in status["pairs"].items() if k not in timed} == {
        k: v for k, v in reply.items() if k not in timed
    }
    assert list(status["pairs"]) == list(reply)  # every key of /status, in its order
    assert status["state"] == "device lost" and status["state_reason"] == "JACK server shut down"
    assert status["device"].startswith("JACK Audio Connection Kit")
    assert status["rate"] == 48000.0
    assert status["osc"]["messages"] == 0 and "fast_path" in status["osc"]
    assert status["midi"] == [
        {
            "port": "MIDI on input 'Launch Control' (rtmidi), mode gate, learning balance",
            "counts": {"cc": 12, "note_on": 3},
            "learning": "balance",
        }
    ]
    assert status["studio"] == {"pages": 1, "refused": {"token": 2}, "refused_total": 2}
    assert status["pairs"]["ch2.intensity"] == 0.3
    assert [e["text"] for e in status["errors"]] == ["/vibsynth/intensity: 1.5 is outside the allowed range [0, 1]"]
    assert status["pairs"]["last_error"] == status["errors"][0]["text"]


def test_without_osc_the_same_parts_are_shown():
    controller = make_controller(1)
    status = studio_status(controller)
    assert status["osc"] is None and status["midi"] == []
    for key in ("version", "channels", "rate", "underflows", "load", "errors", "ch1.intensity"):
        assert key in status["pairs"]
    assert status["state"] == "unknown"  # no output attached


def test_the_page_gets_status_pushes_and_learn_answers(studio, controller):
    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            status = await receive_until(ws, lambda m: m.get("type") == "status")
            await ws.close()
            return status

    http(studio, "GET", "/api/state", token=None)  # one refusal, shown in the next status
    status = run(scenario())
    assert status["studio"]["pages"] == 1
    assert get_json(studio, "/api/status")["studio"]["refused"] == {"token": 1}
    assert midi_learn("intensity") is False  # no MIDI input runs in this process


def test_null_output_is_shown_as_null():
    controller = make_controller(1)
    output = {"name": "null", "state": "streaming", "state_reason": "", "describe": lambda self: "null output"}
    controller.output = type("Null", (), output)()
    server = StudioServer(controller, port=0)
    install_panels(server)
    server.start()
    try:
        assert get_json(server, "/api/status")["state"] == "null"
        controller.output.name = "sounddevice"
        assert get_json(server, "/api/status")["state"] == "running"
    finally:
        server.stop()
