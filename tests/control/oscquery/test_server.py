"""The OSCQuery server over HTTP and WebSocket: queries and their status codes, LISTEN pushes, bad input."""

from __future__ import annotations

import asyncio
import json
import time
import urllib.error
import urllib.request
from typing import Any

import aiohttp
import pytest

from tests.control.oscquery.test_tree import check_node
from tests.control.websocket_frames import client_frame, close_code, handshake, read_upgrade, server_frames
from vibsynth.control.osc.codec import decode_packet, encode_message
from vibsynth.settings.allow_list import parse_allow_list


def get(server, target: str, host: str | None = None) -> tuple[int, Any]:
    request = urllib.request.Request(f"http://127.0.0.1:{server.port}{target}")
    if host is not None:
        request.add_header("Host", host)
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            body = response.read()
            return response.status, json.loads(body) if body else None
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def test_queries_answer_per_the_proposal(server, ctl):
    ctl.set_knob("intensity", 0.375, channels=(1,))
    status, root = get(server, "/")
    assert status == 200 and root["FULL_PATH"] == "/" and "vibsynth" in root["CONTENTS"]
    status, node = get(server, "/vibsynth/ch/2/intensity")
    assert status == 200 and node["TYPE"] == "f" and node["ACCESS"] == 3 and node["VALUE"] == [0.375]
    assert get(server, "/vibsynth/ch/2/intensity?VALUE") == (200, {"VALUE": [0.375]})
    assert get(server, "/vibsynth/ch/2/intensity?RANGE") == (200, {"RANGE": [{"MIN": 0, "MAX": 1}]})
    assert get(server, "/vibsynth/sync?VALUE")[0] == 204  # a trigger holds no value
    assert get(server, "/vibsynth/ch?TYPE")[0] == 204  # a container has no type
    assert get(server, "/vibsynth/ch/2/intensity?NOPE")[0] == 400
    assert get(server, "/vibsynth/ch/2/intensity?VALUE&TYPE")[0] == 400
    assert get(server, "/vibsynth/ch/9/intensity")[0] == 404
    status, info = get(server, "/anything?HOST_INFO")
    assert status == 200 and info["NAME"] == "vibsynth test" and info["OSC_PORT"] == 9570
    assert info["OSC_TRANSPORT"] == "UDP" and info["WS_PORT"] == server.port and info["OSC_IP"] == "127.0.0.1"
    assert info["EXTENSIONS"]["LISTEN"] and info["EXTENSIONS"]["VALUE"] and not info["EXTENSIONS"]["CLIPMODE"]


def test_host_size_and_depth_bounds_refuse_once_and_change_nothing(server, ctl):
    before = ctl.state()
    assert get(server, "/", host=f"evil.example:{server.port}")[0] == 403  # DNS rebinding
    assert get(server, "/", host="127.0.0.1:1")[0] == 403
    assert get(server, "/", host=f"localhost:{server.port}")[0] == 200
    assert get(server, "/" + "a" * 2000)[0] == 414
    assert get(server, "/a" * 40)[0] == 400
    refused = server.refused()
    assert refused["host"] == 2 and refused["too_large"] == 1 and refused["too_deep"] == 1
    assert ctl.state() == before
    assert ctl.error_counts["oscquery.host"] == 2


async def _ws(server, **kwargs):
    session = aiohttp.ClientSession()
    ws = await session.ws_connect(f"http://127.0.0.1:{server.port}/", **kwargs)
    return session, ws


async def _next_osc(ws, timeout=2.0):
    while True:
        msg = await ws.receive(timeout=timeout)
        if msg.type == aiohttp.WSMsgType.BINARY:
            return decode_packet(msg.data)
        if msg.type == aiohttp.WSMsgType.TEXT:
            return json.loads(msg.data)
        raise AssertionError(f"socket closed: {msg}")


def test_listen_streams_values_from_any_side_and_ignore_stops(server, ctl, handler):
    async def run():
        session, ws = await _ws(server)
        try:
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": "/vibsynth/ch/1/intensity"}))
            first = await _next_osc(ws)
            assert first.address == "/vibsynth/ch/1/intensity" and first.args == (0.0,)
            # over OSC (the handler, as the UDP transport calls it)
            handler.handle_batch([(encode_message("/vibsynth/ch/1/intensity", (0.5,), "f"), _Null())])
            moved = await _next_osc(ws)
            assert moved.address == "/vibsynth/ch/1/intensity" and moved.args == (0.5,) and moved.types == "f"
            # from another side (the studio, MIDI, clips all go through the controller)
            ctl.set_knob("intensity", 0.25, channels=(0,), source="studio")
            # pushes are coalesced on the notifier's own clock: one more push of the value already
            # sent may come before the new one (seen on a loaded machine), never another value
            seen = [(await _next_osc(ws)).args[0]]
            while seen[-1] != 0.25 and len(seen) < 5:
                seen.append((await _next_osc(ws)).args[0])
            assert seen[-1] == 0.25 and set(seen) <= {0.5, 0.25}, seen
            # a flood of moves arrives coalesced, the newest last
            for i in range(2000):
                ctl.set_knob("intensity", i / 2000, channels=(0,))
            values = []
            while not values or abs(values[-1] - 1999 / 2000) > 1e-6:
                values.append((await _next_osc(ws)).args[0])
            assert len(values) < 200
            await ws.send_str(json.dumps({"COMMAND": "IGNORE", "DATA": "/vibsynth/ch/1/intensity"}))
            # the socket's frames are handled in order: once the ping's pong is back, IGNORE is applied
            # (a fixed pause was too short on a loaded machine: the 0.75 below was still pushed)
            await ws.send_bytes(encode_message("/vibsynth/ping", (7,), "i"))
            pong = await _next_osc(ws)
            assert pong.address == "/vibsynth/pong" and pong.args == (7,)
            ctl.set_knob("intensity", 0.75, channels=(0,))
            with pytest.raises(asyncio.TimeoutError):
                await ws.receive(timeout=0.3)
        finally:
            await ws.close()
            await session.close()

    asyncio.run(run())


def test_binary_frames_are_osc_packets_with_replies(server, ctl):
    async def run():
        session, ws = await _ws(server)
        try:
            await ws.send_bytes(encode_message("/vibsynth/ch/3/balance", (1.25,), "f"))
            await ws.send_bytes(encode_message("/vibsynth/ch/3/get", ("balance",), "s"))
            reply = await _next_osc(ws)
            assert reply.address == "/vibsynth/ch/3/balance" and reply.args == (1.25,)
            await ws.send_bytes(encode_message("/vibsynth/ch/3/balance", (99.0,), "f"))
            error = await _next_osc(ws)
            assert error.address == "/vibsynth/error"
        finally:
            await ws.close()
            await session.close()

    asyncio.run(run())
    assert ctl.state()[2].balance == 1.25


def test_osc_over_websocket_keeps_the_allow_list(server, ctl):
    server.allow = parse_allow_list(["10.1.2.3"])

    async def run():
        session, ws = await _ws(server)
        try:
            await ws.send_bytes(encode_message("/vibsynth/intensity", (0.5,), "f"))
            answer = await _next_osc(ws)
            assert answer["COMMAND"] == "ERROR" and "osc.allow" in answer["DATA"]
        finally:
            await ws.close()
            await session.close()

    asyncio.run(run())
    assert ctl.state()[0].intensity == 0.0 and server.refused()["not_allowed"] == 1


def test_bad_websocket_input_is_refused_once_each_and_changes_nothing(server, ctl):
    before = ctl.state()

    async def run():
        session, ws = await _ws(server)
        try:
            await ws.send_str("not json")
            assert (await _next_osc(ws))["COMMAND"] == "ERROR"
            await ws.send_str("[" * 5000 + "]" * 5000)  # deeply nested, within the size bound
            assert (await _next_osc(ws))["COMMAND"] == "ERROR"
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": "/no/such"}))
            assert "no OSC method" in (await _next_osc(ws))["DATA"]
            await ws.send_bytes(b"\x00garbage")  # a malformed OSC packet: counted by the handler
            # a LISTEN flood over the per-client bound: the first 256 are taken
            paths = [p for p in server.tree.methods if server.tree.methods[p].value is not None]
            for k in range(300):
                await ws.send_str(
                    json.dumps({"COMMAND": "LISTEN", "DATA": paths[k % len(paths)] + ("" if k < len(paths) else "x")})
                )
            await asyncio.sleep(0.3)
            # still served
            await ws.send_str(json.dumps({"COMMAND": "IGNORE", "DATA": paths[0]}))
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": paths[0]}))
        finally:
            await ws.close()
            await session.close()
        # a frame over the size bound closes that socket only (counted)
        session, ws = await _ws(server)
        try:
            await ws.send_str("x" * 20000)
            msg = await ws.receive(timeout=2)
            assert msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING)
        finally:
            await session.close()
        # a foreign page's socket is refused at the handshake
        with pytest.raises(aiohttp.WSServerHandshakeError):
            await _ws(server, headers={"Origin": "http://evil.example"})

    asyncio.run(run())
    refused = server.refused()
    assert refused["malformed"] == 2 and refused["unknown_path"] >= 1 and refused["origin"] == 1
    assert refused["too_large"] == 1
    assert ctl.state() == before
    assert get(server, "/vibsynth/ch/1/intensity?VALUE") == (200, {"VALUE": [0.0]})


class _Null:
    address = ("127.0.0.1", 1)
    key = ("null",)

    def send(self, data: bytes) -> bool:
        return True


def test_a_taken_default_port_falls_back_and_a_chosen_one_is_an_error(server, tree, handler, ctl):
    from vibsynth.control.oscquery.server import OscQueryServer
    from vibsynth.errors import ConfigError

    second = OscQueryServer(tree, handler, ctl, port=server.port, port_fallback=True)
    second.start()
    try:
        assert second.port != server.port and get(second, "/vibsynth/intensity?TYPE") == (200, {"TYPE": "f"})
    finally:
        second.stop()
    with pytest.raises(ConfigError, match="cannot listen"):
        OscQueryServer(tree, handler, ctl, port=server.port).start()


def test_a_preset_file_added_on_disk_is_path_added_and_removed_path_removed(tmp_path, handler, ctl):
    from vibsynth.control.oscquery.library import LibraryNodes
    from vibsynth.control.oscquery.methods import knob_ranges, method_nodes, reads
    from vibsynth.control.oscquery.server import OscQueryServer
    from vibsynth.control.oscquery.tree import Tree
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    library = PresetLibrary(shipped_presets_dir(), tmp_path)
    tree = Tree(method_nodes(handler, library.names, lambda: []), reads(ctl))
    low, high = knob_ranges(ctl)
    tree.register(LibraryNodes("/vibsynth", library, None, intensity_range=low, balance_range=high))
    srv = OscQueryServer(tree, handler, ctl, port=0)
    srv.start()
    node_path = "/vibsynth/presets/velvet-test"
    file = tmp_path / "velvet-test.yaml"

    async def collect(ws, until: set[tuple[str, str]]) -> set[tuple[str, str]]:
        events: set[tuple[str, str]] = set()
        while not until <= events:
            msg = json.loads((await ws.receive(timeout=5)).data)
            events.add((msg["COMMAND"], msg["DATA"]))
        return events

    async def run():
        session = aiohttp.ClientSession()
        ws = await session.ws_connect(f"http://127.0.0.1:{srv.port}/")
        try:
            await asyncio.sleep(0.2)
            file.write_text(
                "version: 1\nname: velvet-test\nintensity: 0.5\nbalance: -1.0\ndescription: soft\n", encoding="utf-8"
            )
            library.reload()  # what the preset watcher of serve does
            added = await collect(ws, {("PATH_ADDED", node_path), ("PATH_CHANGED", "/vibsynth/ch/4/preset")})
            status, node = get(srv, node_path)
            file.unlink()
            library.reload()
            removed = await collect(ws, {("PATH_REMOVED", node_path)})
            return added, (status, node), removed
        finally:
            await ws.close()
            await session.close()

    try:
        added, (status, node), removed = asyncio.run(run())
        gone = get(srv, node_path)[0]
        status_range, preset_node = get(srv, "/vibsynth/preset?RANGE")
    finally:
        srv.stop()
    # the new file is a node of its own, and every preset node's VALS changed
    changed = {p for c, p in added if c == "PATH_CHANGED"}
    assert {"/vibsynth/preset"} | {f"/vibsynth/ch/{c}/preset" for c in range(1, 5)} <= changed
    assert {c for c, _ in added} <= {"PATH_ADDED", "PATH_CHANGED"}
    assert status == 200 and node["VALUE"] == [0.5, -1.0] and node["ACCESS"] == 1 and node["TYPE"] == "ff"
    assert "soft" in node["DESCRIPTION"] and "/vibsynth/preset s velvet-test" in node["DESCRIPTION"]
    check_node(node)
    assert ("PATH_REMOVED", node_path) in removed and gone == 404
    assert status_range == 200 and "velvet-test" not in preset_node["RANGE"][0]["VALS"]


def test_without_websocket_clients_a_read_sees_the_current_structure(server, presets, monkeypatch):
    from vibsynth.control.oscquery import server as server_module

    assert "velvet" not in get(server, "/vibsynth/preset?RANGE")[1]["RANGE"][0]["VALS"]
    presets.list.append("velvet")
    monkeypatch.setattr(server_module, "REFRESH_S", 0.0)  # the last comparison is older than the period
    assert "velvet" in get(server, "/vibsynth/preset?RANGE")[1]["RANGE"][0]["VALS"]


def test_a_malformed_websocket_frame_closes_that_socket_only_and_is_counted(server, ctl):
    import base64
    import os
    import socket

    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    try:
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall(
            (
                f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        assert b" 101 " in sock.recv(4096).split(b"\r\n", 1)[0]
        sock.sendall(bytes([0x83, 0x85]) + b"\x00\x00\x00\x00" + b"hello")  # reserved opcode 3
        data = sock.recv(4096)  # the server's close frame (1002), then the end of the stream
        assert data[:1] == b"\x88"
    finally:
        sock.close()
    for _ in range(50):
        if server.refused().get("malformed"):
            break
        time.sleep(0.02)
    assert server.refused()["malformed"] == 1 and not server.clients
    assert get(server, "/vibsynth/ch/1/intensity?VALUE") == (200, {"VALUE": [0.0]})


def test_an_adapter_registers_nodes_and_listeners_get_its_values(server, tree):
    from vibsynth.control.oscquery.tree import NodeSpec

    level = [0.0]

    class Avatar:  # what the VRChat bridge registers (/avatar/parameters/...)
        def nodes(self):
            return {"/avatar/parameters/ChestL": NodeSpec("f", "proximity 0..1", lambda ctx: [level[0]])}

    async def run():
        session, ws = await _ws(server)
        try:
            await asyncio.sleep(0.1)
            tree.register(Avatar())
            server.structure_changed()
            assert await _next_osc(ws) == {"COMMAND": "PATH_ADDED", "DATA": "/avatar/parameters/ChestL"}
            await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": "/avatar/parameters/ChestL"}))
            assert (await _next_osc(ws)).args == (0.0,)
            level[0] = 0.5
            server.value_changed("/avatar/parameters/ChestL")
            moved = await _next_osc(ws)
            assert moved.address == "/avatar/parameters/ChestL" and moved.args == (0.5,)
        finally:
            await ws.close()
            await session.close()

    asyncio.run(run())
    assert get(server, "/avatar/parameters/ChestL?VALUE") == (200, {"VALUE": [0.5]})


# ---------------------------------------------------------------------- RFC 6455 framing (issue 31, finding 7)
def _wait_refused(server, reason: str) -> int:
    for _ in range(100):
        if server.refused().get(reason):
            break
        time.sleep(0.02)
    return server.refused().get(reason, 0)


LISTEN = json.dumps({"COMMAND": "LISTEN", "DATA": "/vibsynth/ch/1/intensity"}).encode()


@pytest.mark.parametrize("with_handshake", [False, True], ids=["after", "with-the-handshake"])
def test_an_unmasked_listen_closes_with_1002_and_pushes_nothing(server, ctl, with_handshake):
    """RFC 6455 5.1: a server MUST close the connection upon a client frame that is not masked.

    Sent after the 101 or in the same write as the handshake (aiohttp feeds such bytes to the
    reader as the socket is set up), the LISTEN is never read: no value comes back, ever.
    """
    import socket

    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    upgraded = None
    try:
        if with_handshake:
            sock.sendall(handshake(server.port) + client_frame(0x1, LISTEN, mask=False))
        else:
            sock.sendall(handshake(server.port))
            upgraded = read_upgrade(sock)  # the socket is open: the frame reaches the WebSocket's reader
            sock.sendall(client_frame(0x1, LISTEN, mask=False))
        frames = server_frames(sock, upgraded)
    finally:
        sock.close()
    assert [op for op, _ in frames] == [0x8], frames  # a close frame only: no value was pushed
    assert close_code(frames) == 1002
    assert _wait_refused(server, "unmasked") == 1 and not server.clients
    assert dict(server.status_pairs())["oscquery_listens"] == 0 and server.pushed == 0


def test_a_masked_listen_on_the_same_raw_socket_is_served(server, ctl):
    """The control of the test above: the same bytes, masked, get the value pushed."""
    import socket

    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    try:
        sock.sendall(handshake(server.port) + client_frame(0x1, LISTEN))
        sock.settimeout(2)
        data = b""
        while b"/vibsynth/ch/1/intensity" not in data:
            chunk = sock.recv(4096)
            assert chunk
            data += chunk
        sock.sendall(client_frame(0x8, (1000).to_bytes(2, "big")))
    finally:
        sock.close()
    for _ in range(100):  # counted once the send returned, which may be after the bytes arrived
        if server.pushed:
            break
        time.sleep(0.02)
    assert server.pushed == 1 and not server.refused().get("unmasked")


FRAMING_MUSTS = {
    # RFC 6455 5.2: RSV1-3 MUST be 0 unless an extension defines them (none is negotiated here)
    "rsv1": ([client_frame(0x1, LISTEN, rsv=4)], 1002, "malformed"),
    "rsv3": ([client_frame(0x1, LISTEN, rsv=1)], 1002, "malformed"),
    # 5.5: control frames MUST have a payload of 125 bytes or less and MUST NOT be fragmented
    "ping-126-bytes": ([client_frame(0x9, b"p" * 126)], 1002, "malformed"),
    "fragmented-ping": ([client_frame(0x9, b"p", fin=False), client_frame(0x0, b"q")], 1002, "malformed"),
    # a message is bounded whether it comes in one frame or in fragments (MAX_MESSAGE_BYTES = 16384)
    "fragmented-over-the-bound": (
        [client_frame(0x1, b"[" * 9000, fin=False), client_frame(0x0, b"]" * 9000)],
        1009,
        "too_large",
    ),
    # 5.4: a continuation must continue something
    "lone-continuation": ([client_frame(0x0, LISTEN)], 1002, "malformed"),
    # an unmasked frame in the middle of a fragmented message
    "unmasked-continuation": (
        [client_frame(0x1, b"{", fin=False), client_frame(0x0, LISTEN[1:], mask=False)],
        1002,
        "unmasked",
    ),
}


@pytest.mark.parametrize("case", FRAMING_MUSTS)
def test_each_framing_must_closes_the_socket_and_is_counted(server, ctl, case):
    import socket

    frames, code, reason = FRAMING_MUSTS[case]
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    try:
        sock.sendall(handshake(server.port) + b"".join(frames))
        got = server_frames(sock)
    finally:
        sock.close()
    assert [op for op, _ in got] == [0x8], got
    assert close_code(got) == code
    assert _wait_refused(server, reason) == 1 and not server.clients
    assert server.pushed == 0 and dict(server.status_pairs())["oscquery_listens"] == 0


def test_a_client_that_resets_during_the_handshake_leaves_no_traceback(server, ctl, caplog):
    """A client that sends its upgrade request and resets the connection at once (seen by the soak:
    ``ws.prepare`` met ConnectionResetError and aiohttp logged 'Error handling request' with a
    traceback): nothing is logged above debug, nothing is counted as bad input, and the server
    goes on serving."""
    import logging
    import socket
    import struct

    before = ctl.stats().get("errors", 0) if hasattr(ctl, "stats") else None
    with caplog.at_level(logging.DEBUG):
        for _ in range(20):
            sock = socket.create_connection(("127.0.0.1", server.port))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close = RST
            sock.sendall(handshake(server.port))
            sock.close()
        time.sleep(0.5)
        status, _ = get(server, "/vibsynth/intensity?VALUE")
    assert status == 200
    loud = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not loud, [r.getMessage() for r in loud]
    assert not any(r.exc_info for r in caplog.records)
    assert sum(server.refused().values()) == 0
    if before is not None:
        assert ctl.stats().get("errors", 0) == before
