"""VRChat's avatar parameter values from its OSCQuery tree: parsed like its messages, bounded."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from vibsynth.control.vrchat import values
from vibsynth.control.vrchat.values import MAX_DEPTH, MAX_NODES, parse_avatar, read_avatar
from vibsynth.errors import VibsynthError


def node(path: str, types: str | None = None, value: object = None, contents: dict | None = None) -> dict:
    out: dict = {"FULL_PATH": path, "ACCESS": 3 if types else 0}
    if types is not None:
        out["TYPE"], out["VALUE"] = types, [value]
    if contents is not None:
        out["CONTENTS"] = contents
    return out


def avatar(parameters: dict, avatar_id: str = "avtr_1") -> dict:
    return node(
        "/avatar",
        contents={
            "change": node("/avatar/change", "s", avatar_id),
            "parameters": node("/avatar/parameters", contents=parameters),
        },
    )


def test_values_are_numbers_like_the_messages_and_nested_names_join():
    tree = avatar(
        {
            "Proximity": node("/avatar/parameters/Proximity", "f", 0.25),
            "Touch": node("/avatar/parameters/Touch", "T", True),
            "Off": node("/avatar/parameters/Off", "T", False),
            "Gesture": node("/avatar/parameters/Gesture", "i", 3),
            "Go": node("/avatar/parameters/Go", contents={"Hand": node("/avatar/parameters/Go/Hand", "f", 0.5)}),
            "Odd": node("/avatar/parameters/Odd", "s", "text"),
            "NaN": {"TYPE": "f", "VALUE": ["nan"]},
            "Two": {"TYPE": "ff", "VALUE": [1.0, 2.0]},
            "BoolAsNumber": node("/avatar/parameters/BoolAsNumber", "f", True),
        }
    )
    found = parse_avatar(json.loads(json.dumps(tree)))
    assert found.avatar == "avtr_1"
    assert dict(found.parameters) == {"Proximity": 0.25, "Touch": 1.0, "Off": 0.0, "Gesture": 3.0, "Go/Hand": 0.5}
    assert found.skipped == 4


def test_a_tree_without_parameters_is_empty_and_a_non_node_is_refused():
    assert parse_avatar({"FULL_PATH": "/avatar"}).parameters == {}
    with pytest.raises(VibsynthError, match="not an OSCQuery node"):
        parse_avatar([1, 2])


def test_deep_or_huge_trees_are_refused_with_one_message():
    deep: dict = node("/x", "f", 0.0)
    for _ in range(MAX_DEPTH + 2):
        deep = {"CONTENTS": {"x": deep}}
    with pytest.raises(VibsynthError, match="deeper than"):
        parse_avatar(avatar({"x": deep}))
    wide = {f"P{i}": {"TYPE": "f", "VALUE": [0.0]} for i in range(MAX_NODES + 1)}
    with pytest.raises(VibsynthError, match="more than"):
        parse_avatar(avatar(wide))


class _Server:
    """An HTTP server answering every GET with one fixed body."""

    def __init__(self, body: bytes) -> None:
        payload = body

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                self.send_response(200)
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload)

            def log_message(self, *args: object) -> None:
                pass

        self.http = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(target=self.http.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.http.server_address[1]}/"

    def close(self) -> None:
        self.http.shutdown()
        self.http.server_close()


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"{not json", "not JSON"),
        (b"[" * 100_000 + b"]" * 100_000, "not JSON"),  # past json's own nesting limit
        (b"[1]", "not an OSCQuery node"),
    ],
)
def test_bad_answers_are_one_line_naming_the_url(body, message):
    server = _Server(body)
    try:
        with pytest.raises(VibsynthError, match=message) as info:
            read_avatar(server.url)
        assert server.url.rstrip("/") + "/avatar" in str(info.value) and "\n" not in str(info.value)
    finally:
        server.close()


def test_an_answer_larger_than_the_cap_is_refused(monkeypatch):
    monkeypatch.setattr(values, "AVATAR_CAP", 1000)
    server = _Server(json.dumps(avatar({f"P{i}": node("/p", "f", 0.5) for i in range(100)})).encode())
    try:
        with pytest.raises(VibsynthError, match="larger than"):
            read_avatar(server.url)
    finally:
        server.close()


def test_read_avatar_over_http_and_no_server():
    server = _Server(json.dumps(avatar({"Touch": node("/avatar/parameters/Touch", "T", True)})).encode())
    try:
        assert read_avatar(server.url).parameters == {"Touch": 1.0}
    finally:
        server.close()
    with pytest.raises(VibsynthError, match="no answer"):
        read_avatar(server.url, timeout_s=0.5)
