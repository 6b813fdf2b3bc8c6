"""OSCQuery for serve: built from the discovery: section for a running OSC server, its counters in /status."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.control.osc.server import OscServer
from vibsynth.control.oscquery import adapter, oscquery_of
from vibsynth.settings.config import load_config


def settings(**overrides):
    return load_config(overrides={"osc.port": 0, **overrides}, env={}, user_file=False).settings


@pytest.fixture
def osc():
    ctl = make_controller(channels=2)
    server = OscServer(ctl, port=0)
    server.start()
    yield server
    server.stop()


def test_serve_builds_it_for_the_osc_server_and_status_shows_its_counters(osc):
    service = adapter.create(settings(), SimpleNamespace(oscquery_port=0), osc.controller, osc)
    assert service is not None and service.advertiser is None  # loopback only: not advertised
    service.start()
    try:
        info = service.server.host_info()
        assert info["OSC_PORT"] == osc.port and info["OSC_IP"] == "127.0.0.1"
        assert "/vibsynth/ch/2/intensity" in service.tree.methods
        keys = dict(osc.handler.status_pairs())
        assert keys["oscquery_clients"] == 0 and keys["oscquery_refused"] == 0
        assert service.describe().startswith(f"OSCQuery on http://127.0.0.1:{service.server.port}/")
        assert oscquery_of(osc.controller) is service  # where an adapter registers its nodes
    finally:
        service.stop()
    assert "oscquery_clients" not in dict(osc.handler.status_pairs())
    assert oscquery_of(osc.controller) is None


def test_the_libraries_are_nodes_from_the_first_request(osc, tmp_path):
    from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir
    from vibsynth.settings.library import PresetLibrary, shipped_presets_dir

    presets = PresetLibrary(shipped_presets_dir(), tmp_path)
    clips = ClipLibrary(shipped_clips_dir(), tmp_path)
    service = adapter.create(
        settings(), SimpleNamespace(oscquery_port=0), osc.controller, osc, presets=presets, clips=clips
    )
    paths = set(service.tree.methods)  # before any refresh of the server's own
    assert {f"/vibsynth/presets/{n}" for n in presets.names()} <= paths
    assert {f"/vibsynth/clips/{n}" for n in clips.names()} <= paths


def test_off_switches_and_explicit_interfaces(osc):
    assert adapter.create(settings(), SimpleNamespace(no_discovery=True), osc.controller, osc) is None
    assert adapter.create(settings(**{"discovery.enabled": False}), None, osc.controller, osc) is None
    assert adapter.create(settings(), None, osc.controller, None) is None  # no OSC server: nothing to describe
    chosen = settings(**{"discovery.interfaces": ["10.0.0.7"], "discovery.name": "bench rig"})
    service = adapter.create(chosen, None, osc.controller, osc)
    assert service is not None and service.advertiser is not None  # built, not started: no multicast here
    assert service.advertiser.addresses == ["10.0.0.7"] and service.advertiser.name == "bench rig"
    assert service.advertiser.osc_port == osc.port


def test_notify_over_the_websocket_pushes_from_its_thread_and_ends_with_the_socket(osc):
    import asyncio

    import aiohttp

    from vibsynth.control.osc.codec import Bundle, decode_packet, encode_message, iter_messages

    service = adapter.create(settings(), SimpleNamespace(oscquery_port=0), osc.controller, osc)
    service.start()

    async def run():
        session = aiohttp.ClientSession()
        ws = await session.ws_connect(f"http://127.0.0.1:{service.server.port}/")
        try:
            await ws.send_bytes(encode_message("/vibsynth/notify", (1,), "i"))
            done = decode_packet((await ws.receive(timeout=5)).data)
            assert done.address == "/vibsynth/done" and done.args == ("/vibsynth/notify", 1)
            assert len(osc.notifier) == 1
            osc.controller.set_knob("intensity", 0.75, channels=(1,))  # pushed by the notifier's thread
            while True:
                packet = decode_packet((await ws.receive(timeout=5)).data)
                for push in [m for m, _ in iter_messages(packet)] if isinstance(packet, Bundle) else [packet]:
                    if push.address == "/vibsynth/ch/2/intensity" and push.args == (0.75,):
                        return push.args
        finally:
            await ws.close()
            await session.close()

    try:
        assert asyncio.run(run()) == (0.75,)
        for _ in range(100):
            if len(osc.notifier) == 0:
                break
            asyncio.run(asyncio.sleep(0.02))
        assert len(osc.notifier) == 0  # the subscription ended with the socket
    finally:
        service.stop()
