"""The studio server's HTTP and WebSocket API (a real server on a free port, a fake engine)."""

from __future__ import annotations

import asyncio
import json
import threading

import aiohttp
import pytest

from tests.control.osc.fakes import make_controller
from tests.control.studio.helpers import connect, get_json, http, receive_until, run
from vibsynth.control.studio.commands import MAX_MESSAGE_BYTES
from vibsynth.control.studio.extension import StudioExtension
from vibsynth.control.studio.server import StudioServer
from vibsynth.engine.commands import SetKnob
from vibsynth.errors import ConfigError


def is_type(kind: str, **fields):
    return lambda m: m.get("type") == kind and all(m.get(k) == v for k, v in fields.items())


def test_state_describes_channels_limits_and_knobs(studio, controller):
    controller.set_knob("balance", 1.25, channels=[1])
    state = get_json(studio, "/api/state")
    assert state["channels"] == 2
    assert state["limits"]["balance_min"] == -3.5 and state["limits"]["balance_max"] == 3.5
    assert state["limits"]["glide_max_ms"] == 10000.0
    assert [s["channel"] for s in state["state"]] == [1, 2]
    assert state["state"][1]["balance"] == 1.25 and state["state"][0]["balance"] == 0.0
    assert state["state"][0]["driver"] == "knobs"
    assert state["extensions"] == []


def test_page_moves_reach_the_controller_and_are_acknowledged(studio, controller, library):
    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            hello = await receive_until(ws, is_type("hello"))
            assert hello["channels"] == 2
            await ws.send_json({"type": "knob", "channel": 2, "name": "intensity", "value": 0.42, "id": 7})
            await receive_until(ws, is_type("ack", id=7))
            await ws.send_json({"type": "texture", "channel": 1, "intensity": 0.3, "balance": -1.5, "id": "xy"})
            await receive_until(ws, is_type("ack", id="xy"))
            await ws.send_json({"type": "glide", "channel": None, "value_ms": 250, "id": 8})
            await receive_until(ws, is_type("ack", id=8))
            await ws.send_json({"type": "mute", "channel": 2, "value": True, "id": 9})
            await receive_until(ws, is_type("ack", id=9))
            await ws.send_json({"type": "preset", "channel": 1, "name": "brick", "id": 10})
            await receive_until(ws, is_type("ack", id=10))
            await ws.close()

    run(scenario())
    one, two = controller.state()
    brick = library.get("brick")
    assert two.intensity == 0.42 and two.muted
    assert (one.intensity, one.balance, one.preset) == (brick.intensity, brick.balance, "brick")  # it came last
    assert one.glide_s == two.glide_s == 0.25
    knob = [c for c in controller.engine.commands if isinstance(c, SetKnob) and c.value == 0.42]
    assert knob and knob[0].channels == (1,)


def test_changes_made_elsewhere_are_pushed(studio, controller):
    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))
            thread = threading.Thread(target=lambda: controller.set_knob("balance", 2.5, channels=[0], source="osc"))
            thread.start()
            thread.join()
            pushed = await receive_until(ws, is_type("knob", name="balance"))
            assert pushed == {"type": "knob", "channel": 1, "name": "balance", "value": 2.5, "source": "osc"}
            controller.set_glide(0.5, channels=[1], source="midi")
            glide = await receive_until(ws, is_type("knob", name="glide_ms"))
            assert glide["value"] == 500.0 and glide["channel"] == 2
            controller.panic(source="osc")
            await receive_until(ws, is_type("knob", name="intensity", value=0.0))
            await ws.close()

    run(scenario())


@pytest.mark.parametrize(
    ("message", "says"),
    [
        ("not json", "not JSON"),
        ("[1, 2]", "JSON object"),
        ('{"type": "launch"}', "unknown message type"),
        ('{"type": "knob", "channel": 0, "name": "intensity", "value": 0.5}', "channel must be an integer 1..2"),
        ('{"type": "knob", "channel": 3, "name": "intensity", "value": 0.5}', "channel must be an integer 1..2"),
        ('{"type": "knob", "channel": true, "name": "intensity", "value": 0.5}', "channel must be"),
        ('{"type": "knob", "channel": 1, "name": "volume", "value": 0.5}', "intensity or balance"),
        ('{"type": "knob", "channel": 1, "name": "intensity", "value": NaN}', "finite number"),
        ('{"type": "knob", "channel": 1, "name": "intensity", "value": "0.5"}', "finite number"),
        ('{"type": "knob", "channel": 1, "name": "intensity", "value": 1.5}', "outside the allowed range [0, 1]"),
        ('{"type": "knob", "channel": 1, "name": "balance", "value": 9}', "outside the allowed range [-3.5, 3.5]"),
        ('{"type": "glide", "value_ms": -1}', "outside the allowed range"),
        ('{"type": "mute", "value": "yes"}', "true or false"),
        ('{"type": "preset", "name": "nope"}', "unknown preset 'nope'"),
        ('{"type": "preset", "name": ""}', "preset name"),
        ('{"type": "watch"}', "channel must be an integer 1..2,"),
        ('{"type": "learn", "knob": "glide"}', "intensity or balance"),
        ('{"type": "panic", "id": {"a": 1}}', "id must be"),
    ],
)
def test_malformed_messages_are_answered_and_change_nothing(studio, controller, message, says):
    before = controller.state()

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))
            await ws.send_str(message)
            error = await receive_until(ws, is_type("error"))
            # the page stays connected and usable
            await ws.send_json({"type": "knob", "channel": 1, "name": "balance", "value": 0.5, "id": "after"})
            await receive_until(ws, is_type("ack", id="after"))
            await ws.close()
            return error

    error = run(scenario())
    assert says in error["message"]
    after = controller.state()
    assert after[1] == before[1] and after[0].intensity == before[0].intensity and after[0].preset is None


def test_learn_without_midi_says_so(studio):
    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await ws.send_json({"type": "learn", "knob": "intensity", "id": "learn-intensity"})
            return await receive_until(ws, is_type("error", id="learn-intensity"))

    assert "MIDI learn unavailable" in run(scenario())["message"]


def test_oversize_and_binary_messages_are_refused(studio, controller):
    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await ws.send_bytes(b"\x00\x01")
            error = await receive_until(ws, is_type("error"))
            assert "binary" in error["message"]
            await ws.send_str(json.dumps({"type": "panic", "pad": "x" * MAX_MESSAGE_BYTES}))
            while True:
                msg = await asyncio.wait_for(ws.receive(), 10)
                if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING):
                    return ws.close_code

    assert run(scenario()) == 1009  # message too big
    refused = get_json(studio, "/api/status")["studio"]["refused"]
    assert refused["malformed"] == 1 and refused["too_large"] == 1
    assert controller.state()[0].intensity == 0.0  # the oversize panic was never applied


def test_a_flood_of_moves_lands_on_the_last_value_with_bounded_engine_commands(studio, controller):
    """20,000 moves as fast as the socket takes them: the budget defers, the newest value always lands."""
    count = 20_000

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))
            for n in range(count):
                await ws.send_str(
                    json.dumps({"type": "knob", "channel": 1, "name": "intensity", "value": (n + 1) / count})
                )
            await ws.send_json({"type": "knob", "channel": 1, "name": "balance", "value": 1.0, "id": "end"})
            await receive_until(ws, is_type("knob", name="intensity", value=1.0), timeout=30)
            await ws.close()

    run(scenario())
    assert controller.state()[0].intensity == 1.0
    knobs = [c for c in controller.engine.commands if isinstance(c, SetKnob) and c.name == "intensity"]
    assert len(knobs) <= count
    assert knobs[-1].value == 1.0


def test_commands_after_a_flood_keep_their_order(studio, controller):
    """Moves waiting for the budget never land after a later panic, mute or texture."""

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))
            for n in range(5000):
                await ws.send_str(json.dumps({"type": "knob", "channel": 1, "name": "intensity", "value": n / 5000}))
                await ws.send_str(json.dumps({"type": "texture", "channel": 2, "intensity": n / 5000, "balance": 0.5}))
            await ws.send_json({"type": "knob", "channel": 2, "name": "balance", "value": -2.0})
            await ws.send_json({"type": "panic", "id": "panic"})
            await receive_until(ws, is_type("ack", id="panic"), timeout=30)
            await ws.send_json({"type": "watch", "channel": 1, "id": "later"})
            await receive_until(ws, is_type("ack", id="later"), timeout=30)
            await ws.close()

    run(scenario())
    one, two = controller.state()
    assert one.intensity == 0.0 and two.intensity == 0.0  # the panic came last
    assert two.balance == -2.0  # after the last texture's 0.5


def test_a_panic_is_never_refused_for_the_budget(studio, controller, monkeypatch):
    """The budget never refills (a frozen clock): mutes over it are refused, a panic still lands."""
    import vibsynth.control.studio.server as server_module
    from vibsynth.control.studio.commands import Throttle

    monkeypatch.setattr(server_module, "Throttle", lambda **kw: Throttle(clock=lambda: 0.0, **kw))
    budget = int(Throttle().burst)
    controller.set_knob("intensity", 0.8, channels=[0, 1])

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))
            for n in range(budget):
                await ws.send_json({"type": "mute", "channel": 1, "value": False, "id": n})
            await ws.send_json({"type": "mute", "channel": 1, "value": True, "id": "over"})
            refused = await receive_until(ws, is_type("error", id="over"), timeout=30)
            await ws.send_json({"type": "panic", "id": "panic"})
            await receive_until(ws, is_type("ack", id="panic"), timeout=30)
            await ws.close()
            return refused

    refused = run(scenario())
    assert "too many messages" in refused["message"]
    assert not controller.state()[0].muted  # the refused mute changed nothing
    assert all(s.intensity == 0.0 for s in controller.state())  # the panic landed


def test_pushes_to_a_page_coalesce_under_an_osc_rate_flood(studio, controller):
    """100,000 moves from another thread: the page gets the final values, in far fewer messages."""
    count = 100_000

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws = await connect(session, studio)
            await receive_until(ws, is_type("hello"))

            def flood() -> None:
                for n in range(count):
                    controller.set_knob("intensity", (n + 1) / count, channels=[0], source="osc")

            thread = threading.Thread(target=flood)
            thread.start()
            frames = 0
            while True:
                raw = await asyncio.wait_for(ws.receive(), 30)
                frames += 1
                data = json.loads(raw.data)
                messages = data["messages"] if data["type"] == "batch" else [data]
                if any(m.get("name") == "intensity" and m.get("value") == 1.0 for m in messages):
                    break
            thread.join()
            await ws.close()
            return frames

    frames = run(scenario())
    assert frames < count
    assert studio.hub.posted >= count and studio.hub.dropped == 0


def test_too_many_pages_are_refused(controller, monkeypatch):
    monkeypatch.setattr("vibsynth.control.studio.server.MAX_PAGES", 2)
    server = StudioServer(controller, port=0)
    server.start()
    try:

        async def scenario():
            async with aiohttp.ClientSession() as session:
                first = await connect(session, server)
                second = await connect(session, server)
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await connect(session, server)
                await first.close()
                await second.close()
                return info.value.status

        assert run(scenario()) == 503
    finally:
        server.stop()


def test_static_files_are_a_fixed_list(studio):
    status, headers, body = http(studio, "GET", "/static/js/main.js")
    assert status == 200 and headers["content-type"].startswith("text/javascript")
    assert b"WebSocket" in body
    for path in ["/static/../server.py", "/static/%2e%2e/server.py", "/static/js/../../server.py", "/static/nope.js"]:
        assert http(studio, "GET", path)[0] == 404, path


def test_a_taken_port_is_one_clear_error_or_a_fallback(controller):
    first = StudioServer(controller, port=0)
    first.start()
    try:
        strict = StudioServer(make_controller(1), port=first.port)
        with pytest.raises(ConfigError) as info:
            strict.start()
        message = str(info.value)
        assert f"cannot listen on 127.0.0.1:{first.port}" in message and "--studio-port" in message
        assert "\n" not in message
        fallback = StudioServer(make_controller(1), port=first.port, port_fallback=True)
        fallback.start()
        try:
            assert fallback.port != first.port
            assert f"port {first.port} was in use" in fallback.describe()
            assert http(fallback, "GET", "/api/state")[0] == 200
        finally:
            fallback.stop()
    finally:
        first.stop()


def test_extensions_add_a_tab_and_routes_behind_the_gate(controller, tmp_path):
    from aiohttp import web

    script = tmp_path / "demo.js"
    script.write_text("export function mount(panel, studio) { panel.textContent = 'demo'; }\n")
    seen = []

    def add_routes(app, host):
        async def hello(request):
            host.publish("demo", "greeting", {"hello": True})
            return web.json_response({"channels": host.controller.channels})

        app.router.add_get("/ext/demo/hello", hello)
        seen.append(host)

    ext = StudioExtension(name="demo", title="Demo", script=script, add_routes=add_routes)
    server = StudioServer(controller, port=0, extensions=[ext])
    server.start()
    try:
        state = get_json(server, "/api/state")
        assert state["extensions"] == [{"name": "demo", "title": "Demo", "script": "/ext/demo/tab.js"}]
        status, headers, body = http(server, "GET", "/ext/demo/tab.js")
        assert status == 200 and body == script.read_bytes()
        assert http(server, "GET", "/ext/demo/hello", token=None)[0] == 403

        async def scenario():
            async with aiohttp.ClientSession() as session:
                ws = await connect(session, server)
                await receive_until(ws, is_type("hello"))
                assert json.loads(http(server, "GET", "/ext/demo/hello")[2]) == {"channels": 2}
                pushed = await receive_until(ws, is_type("ext"))
                await ws.close()
                return pushed

        assert run(scenario()) == {"type": "ext", "extension": "demo", "key": "greeting", "data": {"hello": True}}
        assert seen == [server]
    finally:
        server.stop()


def test_extensions_that_break_the_contract_are_refused(controller, tmp_path):
    script = tmp_path / "tab.js"
    script.write_text("export function mount() {}\n")

    async def evil(request):
        return None

    def outside(app, host):
        app.router.add_get("/api/evil", evil)

    with pytest.raises(ConfigError, match="bad-Name"):
        StudioServer(controller, extensions=[StudioExtension("bad-Name", "T", script)])
    with pytest.raises(ConfigError, match="not a .js file"):
        StudioServer(controller, extensions=[StudioExtension("demo", "T", tmp_path / "missing.js")])
    with pytest.raises(ConfigError, match="title"):
        StudioServer(controller, extensions=[StudioExtension("demo", "", script)])
    with pytest.raises(ConfigError, match="same name"):
        twins = [StudioExtension("demo", "A", script), StudioExtension("demo", "B", script)]
        StudioServer(controller, extensions=twins)
    server = StudioServer(controller, port=0, extensions=[StudioExtension("demo", "Demo", script, outside)])
    with pytest.raises(ConfigError, match=r"outside /ext/demo/: /api/evil"):
        server.start()


def test_an_unmasked_page_frame_closes_the_socket_with_1002_and_is_not_applied(studio, controller):
    """RFC 6455 5.1 (issue 31, finding 7): the studio's socket refuses a client frame without a mask."""
    import socket

    from tests.control.studio.helpers import origin
    from tests.control.websocket_frames import client_frame, close_code, handshake, server_frames

    move = json.dumps({"type": "knob", "channel": 1, "name": "intensity", "value": 0.6, "id": 1}).encode()
    with socket.create_connection(("127.0.0.1", studio.port), timeout=10) as sock:
        sock.sendall(handshake(studio.port, f"/ws?token={studio.token}", origin(studio)))
        sock.sendall(client_frame(0x1, move, mask=False))
        frames = server_frames(sock)
    assert close_code(frames) == 1002
    assert b'"ack"' not in b"".join(payload for _, payload in frames)  # hello and its like, no answer to the move
    assert get_json(studio, "/api/status")["studio"]["refused"]["unmasked"] == 1
    assert controller.state()[0].intensity == 0.0


def test_a_page_that_resets_during_the_handshake_leaves_no_traceback(studio, caplog):
    """A page that sends its upgrade request and resets at once (the soak's vanishing clients): no
    'studio: GET /ws failed' traceback, nothing refused, and the studio goes on serving."""
    import logging
    import socket
    import struct
    import time

    from tests.control.studio.helpers import origin
    from tests.control.websocket_frames import handshake

    with caplog.at_level(logging.DEBUG):
        for _ in range(20):
            sock = socket.create_connection(("127.0.0.1", studio.port), timeout=10)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close = RST
            sock.sendall(handshake(studio.port, f"/ws?token={studio.token}", origin(studio)))
            sock.close()
        time.sleep(0.5)
        status = get_json(studio, "/api/status")
    loud = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not loud, [r.getMessage() for r in loud]
    assert not any(r.exc_info for r in caplog.records)
    assert not any(status["studio"]["refused"].values())
