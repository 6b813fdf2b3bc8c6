"""The compiled OSC fast path, over a real socket against a real engine (no PortAudio).

The engine is rendered by the test (explicit time): a command the fast path pushed shows in
the engine's knobs after the next block.
"""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from tests.control.osc.delivered import wait_delivered
from vibsynth.cli import main
from vibsynth.control.controller import Controller
from vibsynth.control.osc import _fast as _oscfast
from vibsynth.control.osc import adapter as osc_adapter
from vibsynth.control.osc.codec import decode_packet, encode_bundle, encode_message
from vibsynth.control.osc.server import OscServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.errors import ConfigError
from vibsynth.formats.basis_file import default_basis
from vibsynth.limits import MAX_CHANNELS, OSC_FAST_ADDRESS_MAX, OSC_PREFIX_MAX
from vibsynth.settings.config import load_config


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=48000.0, loop_seconds=0.5, levels=9, seed=2))


@pytest.fixture
def served(bank):
    engine = Engine(bank, channels=3, glide_s=0.0, max_block=512)
    ctl = Controller(engine, initial_glide_s=0.0)
    server = OscServer(ctl, port=0)
    server.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(2.0)
    try:
        yield engine, ctl, server, client
    finally:
        client.close()
        server.stop()


def roundtrip(client, server, address, *args, types=None):
    """Send, then ask /ping and wait for its answer: everything before it has been handled.

    And until the handler has returned: until then a new datagram queues behind the ping (order),
    and would not take the fast path.
    """
    if address is not None:
        client.sendto(encode_message(address, args, types), ("127.0.0.1", server.port))
    client.sendto(encode_message("/vibsynth/ping", (7,), "i"), ("127.0.0.1", server.port))
    replies = []
    while True:
        msg = decode_packet(client.recvfrom(65536)[0])
        if msg.address.endswith("/pong"):
            wait_delivered(server)
            return replies
        replies.append(msg)


def knobs(engine):
    engine.render(512)
    return engine.knob_values()


def test_common_shapes_take_the_fast_path_and_reach_engine_and_controller(served):
    engine, ctl, server, client = served
    before = server.counters()["fast_path"]
    roundtrip(client, server, "/vibsynth/ch/2/intensity", 0.4, types="f")
    roundtrip(client, server, "/vibsynth/balance", 1.5, types="d")
    roundtrip(client, server, "/vibsynth/ch/3/texture", 0.7, -2, types="fi")
    assert server.counters()["fast_path"] - before == 3
    k = knobs(engine)
    assert k[1][0] == pytest.approx(0.4) and k[0][0] == 0.0
    assert [ch[1] for ch in k[:2]] == [1.5, 1.5]
    assert k[2][0] == pytest.approx(0.7) and k[2][1] == -2.0
    # the controller knows (recorded before /ping reached Python)
    assert ctl.get("intensity", 1) == pytest.approx(0.4)
    assert ctl.get("balance", 0) == 1.5 and ctl.get("balance", 2) == -2.0
    assert ctl.get("intensity", 2) == pytest.approx(0.7)


@pytest.mark.parametrize(
    "address, args, types",
    [
        ("/vibsynth/intensity", (1.5,), "f"),  # out of range
        ("/vibsynth/intensity", (math.nan,), "f"),  # not finite
        ("/vibsynth/balance", (9.0,), "f"),  # beyond the live range
        ("/vibsynth/texture", (0.5,), "f"),  # wrong count
        ("/vibsynth/intensity", ("x",), "s"),  # wrong type
    ],
)
def test_bad_values_go_to_python_and_get_an_error_reply(served, address, args, types):
    engine, ctl, server, client = served
    replies = roundtrip(client, server, address, *args, types=types)
    assert any(r.address.endswith("/error") for r in replies)
    assert server.counters()["fast_path"] == 0
    assert knobs(engine)[0][0] == 0.0 and ctl.get("intensity") == 0.0


def test_arrival_order_is_kept_between_python_and_fast_messages(served):
    engine, ctl, server, client = served
    target = ("127.0.0.1", server.port)
    # a pattern (Python) then an exact address (fast) for the same knob, back to back: the last wins
    for _k in range(50):
        client.sendto(encode_message("/vibsynth/ch/*/intensity", (0.2,), "f"), target)
        client.sendto(encode_message("/vibsynth/ch/1/intensity", (0.6,), "f"), target)
    roundtrip(client, server, None)
    assert knobs(engine)[0][0] == pytest.approx(0.6) and ctl.get("intensity", 0) == pytest.approx(0.6)
    assert knobs(engine)[1][0] == pytest.approx(0.2)


def test_get_after_a_fast_move_answers_the_new_value(served):
    engine, ctl, server, client = served
    target = ("127.0.0.1", server.port)
    client.sendto(encode_message("/vibsynth/ch/1/intensity", (0.35,), "f"), target)
    client.sendto(encode_message("/vibsynth/ch/1/get", ("intensity",), "s"), target)
    msg = decode_packet(client.recvfrom(65536)[0])
    assert msg.args[-1] == pytest.approx(0.35)


def test_timetagged_bundles_are_not_fast_and_keep_their_frame(served):
    engine, ctl, server, client = served
    when = time.time() + 0.5
    seconds = int(when) + 2208988800
    tag = (seconds << 32) | int((when % 1) * (1 << 32))
    bundle = encode_bundle(tag, [encode_message("/vibsynth/intensity", (0.9,), "f")])
    client.sendto(bundle, ("127.0.0.1", server.port))
    roundtrip(client, server, None)
    assert server.counters()["fast_path"] == 0
    assert engine.stats.pending == 1


def test_flood_of_fast_messages_is_lossless_and_notifies(served):
    engine, ctl, server, client = served
    seen = []
    ctl.subscribe(lambda event: seen.append(event))
    values = np.random.default_rng(3).uniform(0, 1, 5000).astype(np.float32)
    target = ("127.0.0.1", server.port)
    out = np.zeros((512, 3), dtype=np.float32)
    for i, v in enumerate(values):
        client.sendto(encode_message("/vibsynth/ch/1/intensity", (float(v),), "f"), target)
        if i % 500 == 0:
            engine.render_into(out)  # keep the ring draining, as the audio thread would
    roundtrip(client, server, None)
    for _ in range(8):
        engine.render_into(out)
    assert server.counters()["fast_path"] == len(values)
    assert engine.knob_values()[0][0] == pytest.approx(float(values[-1]))
    assert ctl.get("intensity", 0) == pytest.approx(float(values[-1]))
    # subscribers hear about the moves, coalesced (at most every 20 ms), ending on the last value
    assert seen and seen[-1].value == pytest.approx(float(values[-1])) and len(seen) < len(values)


def test_allow_list_networks_are_enforced_in_the_compiled_loop(bank):
    engine = Engine(bank, channels=1, max_block=512)
    ctl = Controller(engine)
    server = OscServer(ctl, port=0, allow=["10.0.0.0/8"])
    server.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for _ in range(3):
            client.sendto(encode_message("/vibsynth/intensity", (0.5,), "f"), ("127.0.0.1", server.port))
        deadline = time.monotonic() + 2
        while server.counters()["denied"] < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert server.counters()["denied"] == 3 and server.counters()["fast_path"] == 0
        assert knobs(engine)[0][0] == 0.0
    finally:
        client.close()
        server.stop()


def test_stop_returns_promptly(bank):
    server = OscServer(Controller(Engine(bank, channels=1, max_block=512)), port=0)
    server.start()
    t0 = time.monotonic()
    server.stop()
    assert time.monotonic() - t0 < 1.0


def test_truncated_and_garbage_datagrams_never_take_the_fast_path(served):
    engine, ctl, server, client = served
    good = encode_message("/vibsynth/intensity", (0.5,), "f")
    rng = np.random.default_rng(8)
    target = ("127.0.0.1", server.port)
    for n in range(1, len(good)):
        client.sendto(good[:n], target)
    for _ in range(300):
        data = bytearray(good)
        data[int(rng.integers(len(data)))] = int(rng.integers(256))
        if bytes(data) != good:
            client.sendto(bytes(data), target)
    client.sendto(good + struct.pack(">f", 0.1), target)  # trailing bytes
    roundtrip(client, server, None)
    k = knobs(engine)[0][0]
    # a mutated byte may still form a valid in-range message; only such messages may act
    assert 0.0 <= k <= 1.0 and server.stats.handler_errors == 0


def test_bundles_beyond_the_schedule_cap_get_an_error_and_change_nothing(bank):
    engine = Engine(bank, channels=1, glide_s=0.0, max_block=512, schedule_capacity=20)
    ctl = Controller(engine)
    server = OscServer(ctl, port=0)
    server.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(2.0)
    try:
        when = time.time() + 5.0
        tag = ((int(when) + 2208988800) << 32) | int((when % 1) * (1 << 32))
        # out of time order: later tags first
        for k in range(25):
            bundle = encode_bundle(
                tag - k * (1 << 32) // 100, [encode_message("/vibsynth/intensity", (0.5 - k / 100,), "f")]
            )
            client.sendto(bundle, ("127.0.0.1", server.port))
        replies = roundtrip(client, server, None)
        errors = [r for r in replies if r.address.endswith("/error")]
        assert len(errors) == 5 and all("schedule_capacity" in r.args[1] for r in errors)
        assert engine.stats.pending == 20 and engine.stats.schedule_full == 5
        assert ctl.error_counts.get("osc.schedule_full") == 5
        # the target is the latest-timed accepted value (k = 0), whatever the arrival order
        assert ctl.get("intensity") == pytest.approx(0.5)
        status = dict(server.handler.status_pairs())
        assert status["scheduled_pending"] == 20 and status["schedule_full"] == 5
    finally:
        client.close()
        server.stop()


# ---------------------------------------------------------------------- address length (issue 31, finding 6)
def _receiver(bank, table):
    engine = Engine(bank, channels=MAX_CHANNELS, max_block=512)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        return _oscfast.Receiver(sock.fileno(), engine._core, table, -3.0, 3.0, print, print, None)


def test_the_built_table_holds_addresses_up_to_the_limit_the_settings_use(bank):
    """limits.OSC_FAST_ADDRESS_MAX is the C table's (MAX_ADDR - 1): the longest fits, one more is refused."""
    longest = b"/" + b"a" * (OSC_FAST_ADDRESS_MAX - 1)
    _receiver(bank, [(longest, _oscfast.M_INTENSITY, MAX_CHANNELS - 1)])
    with pytest.raises(ValueError, match="bad address"):
        _receiver(bank, [(longest + b"a", _oscfast.M_INTENSITY, MAX_CHANNELS - 1)])


def _prefix_config(tmp_path, prefix, channels):
    path = tmp_path / "vibsynth.yaml"
    path.write_text(f"osc:\n  port: 0\n  prefix: {prefix}\naudio:\n  channels: {channels}\n", encoding="utf-8")
    return path


def test_a_prefix_one_over_the_limit_is_refused_where_the_config_is_loaded(bank, tmp_path):
    path = _prefix_config(tmp_path, "/" + "p" * OSC_PREFIX_MAX, MAX_CHANNELS)
    with pytest.raises(ConfigError) as caught:
        load_config(path, env={})
    message = str(caught.value)
    assert message.startswith(f"{path}:3: osc.prefix = ")
    assert message.endswith(f"is {OSC_PREFIX_MAX + 1} characters long (allowed: at most {OSC_PREFIX_MAX})")
    with pytest.raises(ConfigError, match=f"at most {OSC_PREFIX_MAX}"):  # a server made in code says the same
        OscServer(Controller(Engine(bank, channels=1, max_block=512)), port=0, prefix="/" + "p" * OSC_PREFIX_MAX)


def test_the_longest_prefix_serves_every_fast_address_on_the_most_channels(bank, tmp_path):
    prefix = "/" + "p" * (OSC_PREFIX_MAX - 1)
    settings = load_config(_prefix_config(tmp_path, prefix, MAX_CHANNELS), env={}).settings
    assert settings.osc.prefix == prefix and len(prefix) == OSC_PREFIX_MAX
    engine = Engine(bank, channels=MAX_CHANNELS, glide_s=0.0, max_block=512)
    ctl = Controller(engine, initial_glide_s=0.0)
    server = osc_adapter.create(settings, None, ctl, None)
    server.start()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as client:
            client.settimeout(2.0)
            target = ("127.0.0.1", server.port)
            client.sendto(encode_message(f"{prefix}/ch/{MAX_CHANNELS}/intensity", (0.25,), "f"), target)
            client.sendto(encode_message(f"{prefix}/ch/{MAX_CHANNELS}/texture", (0.5, 1.25), "ff"), target)
            client.sendto(encode_message(f"{prefix}/ping", (7,), "i"), target)
            assert decode_packet(client.recvfrom(65536)[0]).address == f"{prefix}/pong"
        assert server.counters()["fast_path"] == 2
        k = knobs(engine)
        assert k[MAX_CHANNELS - 1][:2] == (0.5, 1.25) and k[0][:2] == (0.0, 0.0)
    finally:
        server.stop()


def test_serve_starts_with_the_longest_prefix_on_the_most_channels(tmp_path, monkeypatch, capsys):
    """``vibsynth serve`` used to die with 'unexpected ValueError: fast-path table: bad address'."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    prefix = "/" + "p" * (OSC_PREFIX_MAX - 1)
    path = _prefix_config(tmp_path, prefix, MAX_CHANNELS)
    with path.open("a", encoding="utf-8") as f:
        f.write("  rate: 8000\nbank:\n  cache_dir: ''\n  loop_seconds: 0.5\n  levels: 3\nstudio:\n  enabled: false\n")
    assert main(["serve", "--config", str(path), "--output", "null", "--seconds", "0.1", "--no-midi"]) == 0
    assert "OSC on udp://127.0.0.1:" in capsys.readouterr().out
