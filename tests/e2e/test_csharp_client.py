"""End to end: the C# client (clients/csharp/VibsynthClient.cs), compiled with mono's mcs and run
with mono as a console program (tests/clients/csharp/ClientCheck.cs), against a real
``vibsynth serve`` process. What the C# side reports is checked, and so is the server's state,
read independently with the Python client.

Skips with a clear reason when mcs/mono are missing (Debian mono-mcs, mono-runtime), unless
``VIBSYNTH_E2E_REQUIRED=1`` (CI), where it fails. The server renders to the null output: these
tests are about the protocol, not the sound.

Run: ``.venv/bin/python -m pytest tests/e2e/test_csharp_client.py -q``.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

import vibsynth
from tests.clients.mono import build_client_check, build_unity_check, run_mono
from tests.e2e.oscclient import free_udp_port
from tests.e2e.test_osc_e2e import start_serve, stop_serve

#: Runs on the unit tests' workers (tests/e2e/conftest.py): serve on the null output, a mono client; no time measured.
PARALLEL_SAFE = True

pytestmark = pytest.mark.e2e

CHANNELS = 3


@pytest.fixture(scope="module")
def client_check(tmp_path_factory) -> Path:
    """The client and tests/clients/csharp/ClientCheck.cs compiled with mcs (skips without mono)."""
    return build_client_check(tmp_path_factory.mktemp("csharp"))


@pytest.fixture(scope="module")
def server(tmp_path_factory, client_check):
    """A ``vibsynth serve`` with 3 channels on the null output; yields its OSC port."""
    tmp = tmp_path_factory.mktemp("csharp-e2e")
    proc, port = start_serve(tmp, extra_config=f"audio:\n  channels: {CHANNELS}\n")
    try:
        yield port
    finally:
        stop_serve(proc)


@pytest.fixture(scope="module")
def python_client(server):
    with vibsynth.Client(port=server, timeout=5.0) as client:
        yield client


def _texture(text: str) -> tuple[float, float]:
    """``(intensity 0.625, balance -1.5)`` -> (0.625, -1.5)."""
    intensity, balance = text.strip("()").split(", ")
    return float(intensity.split()[1]), float(balance.split()[1])


def test_setters_and_queries_reach_the_engine(server, python_client, client_check):
    seen = run_mono(client_check, "knobs", server)
    assert seen["status.channels"] == str(CHANNELS)
    assert seen["status.version"] == vibsynth.__version__
    assert seen["status.first_key"] == "version"
    assert seen["status.ch2.intensity_present"] == "true"
    assert int(seen["status.pairs"]) == len(python_client.status())
    # what the C# client read back
    assert _texture(seen["ch1.texture"]) == (0.625, -1.5)
    assert (float(seen["ch1.intensity"]), float(seen["ch1.balance"])) == (0.625, -1.5)
    assert (float(seen["ch2.intensity"]), float(seen["ch2.balance"])) == (0.375, 2.25)
    assert float(seen["ch2.glide"]) == 250.0
    assert (seen["ch3.mute"], seen["ch1.mute"]) == ("true", "false")
    assert seen["ch1.preset"] == "none"
    assert seen["ch3.preset"] == "velvet"
    assert seen["ch3.generic"].startswith("/vibsynth/ch/3/intensity f ")
    assert float(seen["async.ch1.intensity"]) == 0.625
    assert _texture(seen["async.ch2.texture"]) == (0.375, 2.25)
    assert seen["async.ch3.mute"] == "true"
    assert seen["malformed"] == "0"
    # the server's state, read by another client
    assert python_client.get("texture", 1) == (0.625, -1.5)
    assert python_client.get("texture", 2) == (0.375, 2.25)
    assert python_client.get("glide", 2) == 250.0
    assert python_client.get("mute", 3) is True
    assert python_client.get("preset", 3) == "velvet"
    assert float(seen["ch3.generic"].split()[-1]) == pytest.approx(python_client.get("intensity", 3))


def test_server_refusals_raise_with_the_servers_text(server, python_client, client_check):
    seen = run_mono(client_check, "errors", server)
    assert seen["get_channel_9.type"] == "VibsynthServerException"
    assert seen["get_channel_9.address"] == "/vibsynth/ch/9/get"
    assert seen["get_channel_9.message"] == "channel 9 out of range (this server has 3 channels: 1..3)"
    assert seen["get_unknown_setting.type"] == "VibsynthServerException"
    assert seen["get_unknown_setting.message"].startswith("unknown setting 'colour'; known: intensity")
    assert seen["get_async_channel_9.type"] == "VibsynthServerException"
    # refused setters are reported together by Sync, in order, and each raised the event once
    assert seen["sync.type"] == "VibsynthServerException"
    assert seen["sync.count"] == "3"
    assert seen["sync.error0"] == "/vibsynth/ch/1/balance: balance 5 is outside the allowed range [-3.5, 3.5]"
    assert seen["sync.error1"] == "/vibsynth/ch/9/intensity: channel 9 out of range (this server has 3 channels: 1..3)"
    assert seen["sync.error2"].startswith("/vibsynth/preset: unknown preset 'no-such-preset'")
    assert seen["events"] == "/vibsynth/ch/1/balance,/vibsynth/ch/9/intensity,/vibsynth/preset"
    assert seen["after_sync.errors"] == "0"
    assert seen["sync_clean"] == "ok"
    # the refused balance changed nothing; the accepted intensity after it applied
    assert seen["ch1.balance"] == "-1.5"
    assert python_client.get("texture", 1) == (0.5, -1.5)


def test_queries_time_out_against_a_closed_port(client_check):
    seen = run_mono(client_check, "timeout", free_udp_port())
    assert seen["get.type"] == "VibsynthTimeoutException"
    assert seen["get.message"].startswith("no reply from 127.0.0.1:") and seen["get.message"].endswith(
        " to /vibsynth/ch/1/get within 0.3 s"
    )
    # each waits its own timeout, not less (the upper bound only catches a wait that never ends:
    # timers fire late on a loaded machine)
    assert 300 <= float(seen["get.elapsed_ms"]) < 300 + 3000
    assert seen["status.type"] == "VibsynthTimeoutException"
    assert 150 <= float(seen["status.elapsed_ms"]) < 150 + 3000
    assert seen["async.completed_on_return"] == "false"  # the async variant does not block
    assert seen["async.type"] == "VibsynthTimeoutException"
    assert 200 <= float(seen["async.elapsed_ms"]) < 200 + 3000
    assert seen["async.request"] == "/vibsynth/ch/2/get"
    # disposing ends a waiting query at once, and later calls fail clearly
    assert seen["disposed.type"] == "ObjectDisposedException"
    assert float(seen["disposed.elapsed_ms"]) < 5000
    assert seen["after_dispose.type"] == "ObjectDisposedException"


def test_bundles_apply_together_or_at_their_time(server, python_client, client_check):
    seen = run_mono(client_check, "bundle", server)
    assert (float(seen["now.ch1"]), float(seen["now.ch2"])) == (0.5, 0.75)
    # the timetagged bundle was scheduled (not refused, not applied at once) and fired later
    assert float(seen["scheduled_delta"]) == 1
    assert float(seen["scheduled_pending"]) >= 1
    assert _texture(seen["later.ch3"]) == (0.875, 1.25)
    assert float(seen["after.scheduled_pending"]) == 0
    assert python_client.get("texture", 3) == (0.875, 1.25)
    # 20 s ahead is beyond the server's 10 s horizon: refused, nothing changed
    assert seen["far.type"] == "VibsynthServerException"
    assert seen["far.address"] == "/vibsynth/ch/1/intensity"
    assert "beyond the schedule horizon of 10 s" in seen["far.message"]
    assert seen["far.ch1"] == "0.5"
    assert seen["twice.type"] == "InvalidOperationException"


def test_threads_and_async_queries_get_their_own_answers(server, client_check):
    seen = run_mono(client_check, "concurrent", server)
    assert seen["threads.errors"] == "none"
    assert seen["threads.done"] == "480"
    assert seen["threads.wrong"] == "0"
    assert seen["async.count"] == "300"
    assert seen["async.mismatched"] == "0"


def test_clips_play_loop_report_and_stop(server, python_client, client_check):
    seen = run_mono(client_check, "clips", server, "heartbeat")
    assert seen["idle"] == "(no clip)"
    # channel 1 loops until stopped, channel 2 plays 3 loop passes at half gain, twice as fast
    assert (seen["ch1.name"], seen["ch1.playing"], seen["ch1.loops_left"]) == ("heartbeat", "true", "-1")
    assert float(seen["ch1.position_ms"]) > 0  # it advanced in the 150 ms since it started
    assert (seen["ch2.name"], seen["ch2.loops_left"]) == ("heartbeat", "2")
    assert seen["ch3"] == "(no clip)"
    assert (seen["ch1.driver"], seen["ch3.driver"]) == ("clip", "knobs")
    assert (seen["status.clips_playing"], seen["status.ch1.clip"]) == ("2", "heartbeat")
    # stopped: the channel glides back to its own knobs
    assert seen["stopped"] == "(no clip)"
    assert seen["stopped.driver"] == "knobs"
    assert _texture(seen["stopped.texture"]) == pytest.approx((0.2, 0.0))
    # a timetagged PlayClipAll: waiting at position 0 before its time, playing after
    assert seen["all.before"] == "(heartbeat at 0 ms, -1 loops left)"
    assert seen["all.after"] == "heartbeat"
    assert seen["all.stopped"] == "(no clip)"
    # refusals with the server's text
    assert seen["refused.count"] == "2"
    assert seen["refused.error0"].startswith("/vibsynth/ch/1/play: unknown clip 'no-such-clip'")
    assert seen["refused.error1"] == "/vibsynth/ch/9/play: channel 9 out of range (this server has 3 channels: 1..3)"
    assert seen["refused.ch1"] == "(no clip)"
    # the server's view, read by the Python client
    assert python_client.status()["clips_playing"] == 0
    assert python_client.get("texture", 1) == pytest.approx((0.2, 0.0))


# ---------------------------------------------------------------------- spatial sources
@pytest.fixture(scope="module")
def glove(tmp_path_factory, client_check):
    """A ``vibsynth serve`` with the glove layout (thumb, index, middle, ring, little, palm); yields its port."""
    tmp = tmp_path_factory.mktemp("csharp-glove")
    proc, port = start_serve(tmp, extra_config="audio:\n  channels: 6\nlayout: glove\n")
    try:
        yield port
    finally:
        stop_serve(proc)


def _plays(client: vibsynth.Client, channel: int, want: tuple[float, float], timeout: float = 5.0) -> tuple:
    """What ``channel`` plays, once it is ``want`` (the mixer updates every 10 ms) or the timeout passed."""
    deadline = time.monotonic() + timeout
    while True:
        got = client.get("texture", channel)
        if got == pytest.approx(want, abs=1e-4) or time.monotonic() > deadline:
            return got
        time.sleep(0.02)


def _source(client: vibsynth.Client, k: int, what: str) -> tuple:
    want = f"/vibsynth/source/{k}/{what}"
    return client.request(f"/vibsynth/source/{k}/get", what, types="s", match=lambda r: r.address == want).args


def test_sources_are_set_queried_scheduled_and_mixed(glove, client_check):
    seen = run_mono(client_check, "sources", glove)
    assert seen["s1.pos"] == "-0.035,0.11,0"
    assert _texture(seen["s1.texture"]) == (0.75, 1.5)
    assert (seen["s1.radius"], seen["s1.rolloff"], seen["s1.on"], seen["s1.speed"]) == (
        "0.03",
        "Smooth",
        "true",
        "false",
    )
    assert seen["s2.pos"] == "0.03,0.04,0.005"
    assert _texture(seen["s2.texture"]) == (0.5, -1.0)
    assert (seen["s2.radius"], seen["s2.rolloff"], seen["s2.on"], seen["s2.speed"]) == (
        "0.12",
        "Phantom",
        "true",
        "true",
    )
    assert _texture(seen["s2.texture2"]) == (0.25, 0.5)
    assert seen["s2.pos2"] == "0.01,-0.02,0"  # two coordinates: z = 0
    assert (seen["s2.preset"], seen["s1.preset"], seen["s2.off"]) == ("velvet", "none", "false")
    assert seen["s1.generic"] == "/vibsynth/source/1/intensity f 0.75"
    # the timetagged move waited for its time
    assert seen["s1.pos_scheduled"] == "-0.035,0.11,0" and seen["s1.pos_after"] == "-0.005,0.12,0"
    # refusals carry the server's text and change nothing
    assert seen["bad_setting.message"].startswith("unknown source setting 'colour'; known: pos, texture")
    assert seen["bad_values.count"] == "2"
    assert seen["bad_values.error0"].startswith("/vibsynth/source/1/preset: unknown preset 'no-such-preset'")
    assert seen["bad_values.error1"] == "/vibsynth/source/1/balance: balance 5 is outside the allowed range [-3.5, 3.5]"
    assert _texture(seen["s1.texture_after_refusals"]) == (0.75, 1.5)
    # the engine's side, read by the Python client: source 1 sits on the index fingertip (channel 2),
    # alone and at distance 0, so channel 2 plays exactly its knobs; the palm is out of its reach
    with vibsynth.Client(port=glove, timeout=5.0) as python_client:
        assert _source(python_client, 1, "pos") == pytest.approx((-0.035, 0.11, 0.0))
        assert _source(python_client, 2, "on") == (0,)
        assert _plays(python_client, 2, (0.75, 1.5)) == pytest.approx((0.75, 1.5), abs=1e-4)
        assert python_client.get("texture", 6) == (0.0, 0.0)


def test_the_unity_example_drives_a_source_on_a_real_server(glove, tmp_path):
    seen = run_mono(build_unity_check(tmp_path), "server", glove)
    # the contact at world (1.01, 0, 2.02), the layout's origin at (1, 0, 2)
    assert [float(v) for v in seen["pos"].split(",")] == pytest.approx([0.01, 0.0, 0.02], abs=1e-6)
    assert seen["on"] == "true" and _texture(seen["texture"]) == pytest.approx((0.7, -1.0))
    assert (float(seen["radius"]), seen["rolloff"], seen["speed_mode"]) == (pytest.approx(0.04), "Phantom", "false")
    assert [float(v) for v in seen["pos2"].split(",")] == pytest.approx([0.03, 0.0, 0.01], abs=1e-6)
    assert seen["on_after_exit"] == "false"
    assert seen["warnings"] == "0"
