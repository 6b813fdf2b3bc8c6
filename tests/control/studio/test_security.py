"""Attacks on the studio: no token, wrong token, foreign Origin or Host, oversize bodies and uploads."""

from __future__ import annotations

import json
import threading

import aiohttp
import pytest

from tests.control.studio.helpers import connect, get_json, http, origin, raw_request, run
from vibsynth.control.studio.security import BODY_CAP, UPLOAD_CAP, Gate, check_token, new_token
from vibsynth.errors import ParameterError


def refused(studio) -> dict[str, int]:
    return get_json(studio, "/api/status")["studio"]["refused"]


@pytest.mark.parametrize("path", ["/", "/api/state", "/api/status", "/static/js/main.js", "/ws", "/nope"])
def test_every_route_needs_the_token(studio, path):
    status, headers, body = http(studio, "GET", path, token=None)
    assert status == 403
    assert b"token" in body
    status, _, _ = http(studio, "GET", path, token="x" * 32)
    assert status == 403
    assert refused(studio)["token"] == 2


def test_the_url_token_becomes_an_http_only_strict_cookie(studio):
    status, headers, body = http(studio, "GET", f"/?token={studio.token}", token=None)
    assert status == 303 and headers["location"] == "/"
    cookie = headers["set-cookie"]
    name = f"vibsynth_studio_{studio.port}"
    assert cookie.startswith(f"{name}={studio.token};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie
    status, headers, body = http(studio, "GET", "/", token=None, headers={"Cookie": f"{name}={studio.token}"})
    assert status == 200
    assert b'data-testid="intensity"' in body
    assert "frame-ancestors 'none'" in headers["content-security-policy"]
    # a wrong token in the URL sets nothing
    status, headers, _ = http(studio, "GET", "/?token=" + "a" * 32, token=None)
    assert status == 403 and "set-cookie" not in headers
    # another studio's cookie (another port) is not ours
    other = f"vibsynth_studio_{studio.port + 1}={studio.token}"
    assert http(studio, "GET", "/api/state", token=None, headers={"Cookie": other})[0] == 403


def test_a_foreign_host_header_is_refused_before_the_token(studio):
    """DNS rebinding: evil.example resolving to 127.0.0.1 reaches the port with its own Host."""
    status, _, body = http(studio, "GET", "/api/state", host=f"evil.example:{studio.port}")
    assert status == 403 and b"Host" in body
    assert http(studio, "GET", "/api/state", host=f"localhost:{studio.port}")[0] == 200
    assert http(studio, "GET", "/api/state", host=f"127.0.0.1:{studio.port + 1}")[0] == 403
    assert refused(studio)["host"] == 2


def test_the_websocket_checks_token_and_origin(studio, controller):
    async def attempt(**kwargs) -> int:
        async with aiohttp.ClientSession() as session:
            try:
                ws = await connect(session, studio, **kwargs)
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status
            await ws.close()
            return 101

    assert run(attempt()) == 101
    assert run(attempt(token=None)) == 403
    assert run(attempt(token="y" * 40)) == 403
    assert run(attempt(origin_header="http://evil.example")) == 403
    assert run(attempt(origin_header=f"http://localhost:{studio.port + 1}")) == 403
    assert run(attempt(origin_header=None)) == 403  # a browser always sends one
    counts = refused(studio)
    assert counts["origin"] == 3 and counts["token"] == 2
    assert controller.state()[0].intensity == 0.0


def test_state_changes_from_a_foreign_origin_are_refused(studio):
    status, _, _ = http(studio, "POST", "/api/presets", headers={"Origin": "http://evil.example"}, body=b"{}")
    assert status == 403
    assert refused(studio)["origin"] == 1


def test_oversize_bodies_are_refused_from_their_length(studio):
    big = b"x" * (BODY_CAP + 1)
    status, _, body = http(studio, "POST", "/api/presets", body=big, headers={"Content-Type": "application/json"})
    assert status == 413 and b"over the limit" in body
    assert refused(studio)["too_large"] == 1


def test_a_1_gb_upload_is_refused_before_its_body_is_sent(studio):
    """The answer comes while the client has sent only the head: nothing of the gigabyte is read."""
    head = (
        f"POST /api/recording HTTP/1.1\r\nHost: 127.0.0.1:{studio.port}\r\n"
        f"Authorization: Bearer {studio.token}\r\nContent-Type: audio/wav\r\n"
        f"Content-Length: {1 << 30}\r\n\r\n"
    ).encode()
    answer = raw_request(studio.port, head)
    assert answer.startswith(b"HTTP/1.1 413")
    assert str(UPLOAD_CAP).encode() in answer


def test_tokens_given_by_the_user_are_checked():
    assert len(new_token()) >= 32 and new_token() != new_token()
    assert check_token("a" * 16) == "a" * 16
    for bad in ["short", "a" * 257, "has space in it!!!", "ünïcödé-töken-123", "a/b" * 8]:
        with pytest.raises(ParameterError, match="16-256 characters"):
            check_token(bad)


def test_token_comparison_rejects_non_ascii_and_empty():
    gate = Gate("t" * 20, port=1, bind_host="127.0.0.1")
    assert gate.token_ok("t" * 20)
    assert not gate.token_ok("")
    assert not gate.token_ok(None)
    assert not gate.token_ok("ţ" * 20)
    assert not gate.token_ok("t" * 21)


def test_non_loopback_binds_accept_any_host_but_still_need_the_token():
    gate = Gate("t" * 20, port=9571, bind_host="0.0.0.0")
    assert gate.host_ok("studio.lan:9571")
    loop = Gate("t" * 20, port=9571, bind_host="127.0.0.1")
    assert loop.host_ok("127.0.0.1:9571") and loop.host_ok("localhost:9571") and loop.host_ok("[::1]:9571")
    assert not loop.host_ok("studio.lan:9571") and not loop.host_ok("127.0.0.1") and not loop.host_ok(None)


def test_refusals_are_counted_safely_from_many_threads(studio):
    def hammer() -> None:
        for _ in range(20):
            http(studio, "GET", "/api/state", token=None)

    threads = [threading.Thread(target=hammer) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    status = json.loads(http(studio, "GET", "/api/status")[2])
    assert status["studio"]["refused"]["token"] == 80
    assert status["studio"]["refused_total"] == 80
    assert origin(studio).startswith("http://127.0.0.1:")
