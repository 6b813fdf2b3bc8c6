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

from pathlib import Path

import pytest

import vibsynth
from tests.clients.mono import build_client_check, run_mono
from tests.e2e.oscclient import free_udp_port
from tests.e2e.test_osc_e2e import start_serve, stop_serve

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
