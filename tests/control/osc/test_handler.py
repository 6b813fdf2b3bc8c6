"""Unit tests of the OSC server: codec, patterns, handlers (decoded messages and raw bytes), no socket
except for the small transport tests at the end."""

from __future__ import annotations

import argparse
import math
import socket
import struct
import time

import pytest

from tests.control.osc.fakes import FakePeer, make_controller, send
from vibsynth.control.osc import adapter as osc_adapter
from vibsynth.control.osc import handler as osc_handler
from vibsynth.control.osc.address import AddressSpace, compile_pattern, normalize_prefix
from vibsynth.control.osc.clock import StreamClock
from vibsynth.control.osc.codec import (
    IMMEDIATE,
    Bundle,
    MalformedPacket,
    Message,
    decode_packet,
    encode_bundle,
    encode_message,
    ntp_to_unix,
    unix_to_ntp,
)
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.server import OscServer
from vibsynth.control.osc.speed import SpeedCurve
from vibsynth.control.osc.transport import SlipDecoder, slip_encode
from vibsynth.control.osc.workers import Notifier, SyncWorker
from vibsynth.engine.commands import Panic, SetGlide, SetKnob, SetMute
from vibsynth.errors import ConfigError, ParameterError
from vibsynth.settings.config import load_config


# ---------------------------------------------------------------------- codec
def test_codec_round_trip_every_type():
    data = encode_message("/a/b", (1, 2.5, "héllo", b"\x01\x02\x03", None, 2**40, 1.25, 7), "ifsbNhdt")
    msg = decode_packet(data)
    assert isinstance(msg, Message)
    assert msg.address == "/a/b" and msg.types == "ifsbNhdt"
    assert msg.args == (1, 2.5, "héllo", b"\x01\x02\x03", None, 2**40, 1.25, 7)


def test_codec_booleans_and_no_typetag():
    assert decode_packet(encode_message("/x", (), "TFI")).args == (True, False, math.inf)
    assert decode_packet(b"/x\x00\x00").args == ()


def test_codec_arrays():
    data = b"/x\x00\x00" + b",[ii]\x00\x00\x00" + struct.pack(">ii", 1, 2)
    assert decode_packet(data).args == ((1, 2),)


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"/x\x00",  # not a multiple of 4
        b"/abc",  # unterminated address
        b"x\x00\x00\x00",  # neither message nor bundle
        b"/x\x00\x00,i\x00\x00",  # int missing
        b"/x\x00\x00,f\x00\x00\x00\x00",  # truncated float
        b"/x\x00\x00,q\x00\x00",  # unknown type tag
        b"/x\x00\x00i\x00\x00\x00",  # type tags without comma
        b"/x\x00\x00,s\x00\x00abcd",  # unterminated string
        b"/\xff\xfe\x00,\x00\x00\x00",  # address not UTF-8
        b"/x\x00\x00,[i\x00" + b"\x00\x00\x00\x01",  # unbalanced [
        b"/x\x00\x00,]\x00\x00",  # unbalanced ]
        b"/x\x00\x00,b\x00\x00\xff\xff\xff\xff",  # negative blob size
        b"/x\x00\x00,b\x00\x00\x00\x00\x00\x10",  # blob runs past the end
        b"/x\x00\x00,i\x00\x00\x00\x00\x00\x01\x00\x00\x00\x00",  # trailing bytes
        b"#bundle\x00\x00\x00\x00",  # header truncated
        b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\xff\xff\xff\xfc" + b"/x\x00\x00",  # negative element size
        b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\x00\x00\x00\x00",  # zero element size
        b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\x00\x00\x00\x40" + b"/x\x00\x00",  # element past the end
        b"#bundle\x00" + b"\x00" * 7 + b"\x01" + b"\x00\x00\x00\x06" + b"/x\x00\x00\x00\x00\x00\x00",  # size % 4
    ],
)
def test_codec_rejects_malformed(data):
    with pytest.raises(MalformedPacket):
        decode_packet(data)


def test_codec_limits_bundle_nesting():
    inner = encode_message("/x")
    for _ in range(8):
        inner = encode_bundle(IMMEDIATE, [inner])
    assert isinstance(decode_packet(inner), Bundle)
    with pytest.raises(MalformedPacket, match="nested"):
        decode_packet(encode_bundle(IMMEDIATE, [inner]))


def test_ntp_round_trip():
    now = 1_800_000_000.123456
    assert abs(ntp_to_unix(unix_to_ntp(now)) - now) < 1e-6


def test_encode_rejects_bad_arguments():
    with pytest.raises(ParameterError):
        encode_message("/x", (1,), "ii")
    with pytest.raises(ParameterError):
        encode_message("/x", (object(),))


# ---------------------------------------------------------------------- patterns
@pytest.mark.parametrize(
    "pattern, expected",
    [
        ("/vibsynth/ch/*/balance", {1, 2, 3, 4}),
        ("/vibsynth/ch/{1,3}/balance", {1, 3}),
        ("/vibsynth/ch/[2-3]/balance", {2, 3}),
        ("/vibsynth/ch/[0-3]/balance", {1, 2, 3}),
        ("/vibsynth/ch/[!1]/balance", {2, 3, 4}),
        ("/vibsynth/ch/?/bal*", {1, 2, 3, 4}),
        ("/vibsynth/ch/9/balance", set()),
        ("/vibsynth/ch/1*/balance", {1}),
    ],
)
def test_pattern_matching_channels(pattern, expected):
    space = AddressSpace("/vibsynth", 4)
    routes = space.match(pattern)
    assert {r.channel + 1 for r in routes} == expected
    assert all(r.method == "balance" for r in routes)


def test_pattern_star_does_not_cross_slash():
    space = AddressSpace("/vibsynth", 2)
    assert space.match("/vibsynth/*") and all(r.channel is None for r in space.match("/vibsynth/*"))
    assert space.match("/*/intensity")[0].method == "intensity"


@pytest.mark.parametrize("bad", ["/vibsynth/ch/[1/x", "/vibsynth/{a,b", "/vibsynth/]", "/x/" + "*" * 300])
def test_pattern_errors(bad):
    with pytest.raises(ParameterError):
        compile_pattern(bad)


def test_prefix_validation():
    assert normalize_prefix("/haptics/") == "/haptics"
    assert normalize_prefix("") == ""
    for bad in ("vibsynth", "/a b", "/a*"):
        with pytest.raises(ConfigError):
            normalize_prefix(bad)


def test_group_merges_channels():
    space = AddressSpace("/p", 4)
    groups = space.group(space.match("/p/ch/{1,3}/intensity"))
    assert groups == [("intensity", (0, 2))]


# ---------------------------------------------------------------------- knobs
def test_intensity_all_channels(handler, ctl, peer):
    send(handler, peer, "/vibsynth/intensity", 0.5)
    assert [s.intensity for s in ctl.state()] == [0.5] * 4
    assert ctl.engine.commands[-1] == SetKnob("intensity", 0.5, None, None, None)
    assert peer.sent == []


def test_intensity_accepts_int_and_double(handler, ctl, peer):
    send(handler, peer, "/vibsynth/intensity", 1)
    assert ctl.get("intensity", 0) == 1.0
    send(handler, peer, "/vibsynth/balance", 0.25, types="d")
    assert ctl.get("balance", 3) == 0.25


def test_per_channel_addresses_are_one_based(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/2/intensity", 0.75)
    assert [s.intensity for s in ctl.state()] == [0.0, 0.75, 0.0, 0.0]
    assert ctl.engine.commands[-1].channels == (1,)


def test_pattern_becomes_one_command(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/{1,3}/balance", -1.5)
    assert [s.balance for s in ctl.state()] == [-1.5, 0.0, -1.5, 0.0]
    assert len(ctl.engine.commands) == 1 and ctl.engine.commands[0].channels == (0, 2)
    send(handler, peer, "/vibsynth/ch/*/intensity", 0.2)
    assert ctl.engine.commands[-1].channels is None  # every channel: the engine's "all"


def test_texture_sets_both(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/4/texture", 0.6, 1.0)
    assert (ctl.get("intensity", 3), ctl.get("balance", 3)) == (pytest.approx(0.6), 1.0)


def test_glide_is_in_ms(handler, ctl, peer):
    send(handler, peer, "/vibsynth/glide", 150.0)
    assert ctl.get("glide", 0) == pytest.approx(0.15)
    assert ctl.engine.commands[-1] == SetGlide(pytest.approx(0.15), None, None)
    send(handler, peer, "/vibsynth/glide", 20000.0)
    assert peer.errors() and "glide (ms)" in peer.errors()[0][1]
    assert ctl.get("glide", 0) == pytest.approx(0.15)


@pytest.mark.parametrize(
    "args, types, muted", [((1,), "i", True), ((0,), "i", False), ((), "T", True), ((1.0,), "f", True)]
)
def test_mute(handler, ctl, peer, args, types, muted):
    handler.handle_packet(encode_message("/vibsynth/ch/3/mute", args, types), peer)
    assert ctl.get("mute", 2) is muted and ctl.get("mute", 0) is False
    assert ctl.engine.commands[-1] == SetMute(muted, (2,), None)


def test_mute_rejects_other_numbers(handler, ctl, peer):
    send(handler, peer, "/vibsynth/mute", 2)
    assert peer.errors() == [("/vibsynth/mute", "mute must be 0 or 1, got 2")]
    assert ctl.engine.commands == []


def test_panic_and_button_release(handler, ctl, peer):
    send(handler, peer, "/vibsynth/intensity", 0.5)
    send(handler, peer, "/vibsynth/panic", 0)
    assert ctl.get("intensity", 0) == 0.5
    send(handler, peer, "/vibsynth/panic")
    assert ctl.get("intensity", 0) == 0.0 and isinstance(ctl.engine.commands[-1], Panic)
    assert peer.sent == []


def test_preset_all_and_per_channel(handler, ctl, peer):
    send(handler, peer, "/vibsynth/preset", "silk")
    assert ctl.get("preset", 3) == "silk" and ctl.get("intensity", 0) == pytest.approx(0.3)
    send(handler, peer, "/vibsynth/ch/2/preset", "sand")
    assert [s.preset for s in ctl.state()] == ["silk", "sand", "silk", "silk"]
    send(handler, peer, "/vibsynth/preset", "nope")
    assert peer.errors()[0][0] == "/vibsynth/preset" and "unknown preset" in peer.errors()[0][1]
    assert ctl.error_counts["osc.preset"] == 1


# ---------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "address, args, types, kind, fragment",
    [
        ("/vibsynth/volume", (0.5,), "f", "osc.unknown_address", "unknown address"),
        (
            "/vibsynth/ch/5/intensity",
            (0.5,),
            "f",
            "osc.unknown_address",
            "channel 5 out of range (this server has 4 channels: 1..4)",
        ),
        ("/vibsynth/ch/0/intensity", (0.5,), "f", "osc.unknown_address", "channel 0 out of range"),
        (
            "/vibsynth/ch/1/intensty",
            (0.5,),
            "f",
            "osc.unknown_address",
            "unknown address (did you mean .../intensity?)",
        ),
        ("/vibsynth/ch/x/intensity", (0.5,), "f", "osc.unknown_address", "unknown address"),
        ("/vibsynth/intensity", (), "", "osc.bad_arguments", "expects 1 argument"),
        ("/vibsynth/intensity", (0.1, 0.2), "ff", "osc.bad_arguments", "expects 1 argument"),
        ("/vibsynth/intensity", ("loud",), "s", "osc.bad_arguments", "must be a number"),
        ("/vibsynth/intensity", (), "T", "osc.bad_arguments", "must be a number"),
        ("/vibsynth/intensity", (float("nan"),), "f", "osc.invalid_value", "finite"),
        ("/vibsynth/balance", (float("inf"),), "d", "osc.invalid_value", "finite"),
        ("/vibsynth/intensity", (), "I", "osc.bad_arguments", "must be a number"),
        ("/vibsynth/intensity", (1.5,), "f", "osc.invalid_value", "outside the allowed range"),
        ("/vibsynth/balance", (-9.0,), "f", "osc.invalid_value", "outside the allowed range"),
        ("/vibsynth/texture", (0.5,), "f", "osc.bad_arguments", "expects 2"),
        ("/vibsynth/texture", (0.5, 99.0), "ff", "osc.invalid_value", "balance"),
        ("/vibsynth/preset", (3,), "i", "osc.bad_arguments", "must be a string"),
        ("/vibsynth/speed", (-1.0,), "f", "osc.invalid_value", ">= 0"),
        ("/vibsynth/ch/[1/intensity", (0.5,), "f", "osc.bad_pattern", "unbalanced"),
    ],
)
def test_errors_reply_count_and_change_nothing(handler, ctl, peer, address, args, types, kind, fragment):
    before = ctl.state()
    handler.handle_packet(encode_message(address, args, types), peer)
    assert ctl.state() == before and ctl.engine.commands == []
    assert len(peer.errors()) == 1
    err_address, message = peer.errors()[0]
    assert err_address == address and fragment in message
    assert ctl.error_counts == {kind: 1}
    assert handler.stats.errors == 1


def test_texture_is_atomic(handler, ctl, peer):
    send(handler, peer, "/vibsynth/texture", 0.5, 9.0)
    assert ctl.get("intensity", 0) == 0.0  # intensity valid, balance not: neither changes


def test_malformed_datagram_counted_without_reply(handler, ctl, peer, caplog):
    caplog.set_level("DEBUG", logger="vibsynth.control.osc")
    handler.handle_packet(b"/vibsynth/intensity\x00,f\x00\x00\x3f", peer)
    assert handler.stats.malformed == 1 and ctl.error_counts == {"osc.malformed": 1}
    assert peer.sent == [] and "malformed" in caplog.text


def test_error_replies_are_rate_limited(ctl, peer):
    handler = OscHandler(ctl, error_reply_rate=5)
    for _ in range(50):
        send(handler, peer, "/nowhere", 1)
    assert 5 <= len(peer.sent) < 50
    assert handler.stats.errors == 50 and ctl.error_counts["osc.unknown_address"] == 50
    assert handler.stats.error_replies_suppressed == 50 - len(peer.sent)


def test_custom_prefix(ctl, peer):
    handler = OscHandler(ctl, prefix="/haptics")
    send(handler, peer, "/haptics/ch/1/intensity", 0.4)
    send(handler, peer, "/vibsynth/intensity", 0.4)
    assert ctl.get("intensity", 0) == pytest.approx(0.4) and ctl.get("intensity", 1) == 0.0
    assert peer.messages()[0].address == "/haptics/error"


# ---------------------------------------------------------------------- speed
def test_speed_curve_default_points():
    curve = SpeedCurve([[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]])
    assert curve.intensity(0.0) == 0.0
    assert curve.intensity(10.0) == pytest.approx(0.35)
    assert curve.intensity(30.0) == pytest.approx(0.475)
    assert curve.intensity(1000.0) == 1.0
    assert curve.balance_shift(1000.0) == 0.0


@pytest.mark.parametrize("points", [[], [[0, 0.0], [0, 1.0]], [[10, 0.5], [5, 0.6]], [[0, 1.5]], [[-1, 0.2]], "x"])
def test_speed_curve_rejects_bad_config(points):
    with pytest.raises(ConfigError):
        SpeedCurve(points)


def test_speed_sets_intensity_zero_is_silence(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/1/speed", 50.0)
    assert ctl.get("intensity", 0) == pytest.approx(0.6) and ctl.get("intensity", 1) == 0.0
    send(handler, peer, "/vibsynth/ch/1/speed", 0)
    assert ctl.get("intensity", 0) == 0.0


def test_speed_balance_shift_keeps_base(ctl, peer):
    curve = SpeedCurve([[0, 0.0], [300, 1.0]], balance_per_decade=0.5)
    handler = OscHandler(ctl, speed_curve=curve)
    send(handler, peer, "/vibsynth/ch/1/balance", 1.0)
    send(handler, peer, "/vibsynth/ch/1/speed", 1000.0)
    assert ctl.get("balance", 0) == pytest.approx(1.5)
    send(handler, peer, "/vibsynth/ch/1/speed", 1000.0)  # not cumulative
    assert ctl.get("balance", 0) == pytest.approx(1.5)
    send(handler, peer, "/vibsynth/ch/1/speed", 50.0)
    assert ctl.get("balance", 0) == pytest.approx(1.0)
    assert ctl.get("balance", 1) == 0.0
    handler.close()


# ---------------------------------------------------------------------- queries
def test_get_global_and_per_channel(handler, ctl, peer):
    send(handler, peer, "/vibsynth/intensity", 0.5)
    send(handler, peer, "/vibsynth/get", "intensity")
    assert [(m.address, m.args) for m in peer.messages()] == [("/vibsynth/intensity", (0.5,))]
    peer.clear()
    send(handler, peer, "/vibsynth/ch/3/intensity", 0.25)
    send(handler, peer, "/vibsynth/get", "intensity")
    assert [(m.address, m.args) for m in peer.messages()] == [
        ("/vibsynth/ch/1/intensity", (0.5,)),
        ("/vibsynth/ch/2/intensity", (0.5,)),
        ("/vibsynth/ch/3/intensity", (0.25,)),
        ("/vibsynth/ch/4/intensity", (0.5,)),
    ]
    peer.clear()
    send(handler, peer, "/vibsynth/ch/3/get", "texture")
    send(handler, peer, "/vibsynth/get", "glide")
    send(handler, peer, "/vibsynth/get", "mute")
    send(handler, peer, "/vibsynth/get", "preset")
    got = [(m.address, m.types, m.args) for m in peer.messages()]
    assert got == [
        ("/vibsynth/ch/3/texture", "ff", (0.25, 0.0)),
        ("/vibsynth/glide", "f", (pytest.approx(20.0),)),
        ("/vibsynth/mute", "i", (0,)),
        ("/vibsynth/preset", "s", ("",)),
    ]


def test_get_driver_names_the_layer_that_plays(handler, ctl, peer):
    ctl.drive("clip", channels=[1], intensity=0.7, balance=1.0)
    send(handler, peer, "/vibsynth/ch/2/get", "driver")
    send(handler, peer, "/vibsynth/get", "driver")
    got = [(m.address, m.types, m.args) for m in peer.messages()]
    assert got[0] == ("/vibsynth/ch/2/driver", "s", ("clip",))
    assert got[1:] == [(f"/vibsynth/ch/{n}/driver", "s", ("clip" if n == 2 else "knobs",)) for n in range(1, 5)]
    peer.clear()
    ctl.release("clip", channels=[1])
    send(handler, peer, "/vibsynth/get", "driver")
    assert [(m.address, m.args) for m in peer.messages()] == [("/vibsynth/driver", ("knobs",))]


def test_get_reply_is_a_valid_setter(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/2/balance", -2.0)
    send(handler, peer, "/vibsynth/ch/2/get", "balance")
    reply = peer.sent[-1]
    other = make_controller(4)
    OscHandler(other).handle_packet(reply, FakePeer())
    assert other.get("balance", 1) == -2.0


def test_get_unknown_setting(handler, peer):
    send(handler, peer, "/vibsynth/get", "volume")
    assert "unknown setting" in peer.errors()[0][1]


def test_status_reply(handler, ctl, peer):
    send(handler, peer, "/vibsynth/ch/2/intensity", 0.3)
    send(handler, peer, "/vibsynth/nope")
    peer.clear()
    send(handler, peer, "/vibsynth/status")
    (msg,) = peer.messages()
    assert msg.address == "/vibsynth/status.reply"
    pairs = dict(zip(msg.args[::2], msg.args[1::2]))
    assert pairs["channels"] == 4 and pairs["rate"] == 48000.0 and pairs["version"]
    assert pairs["errors"] == 1 and pairs["ch2.intensity"] == pytest.approx(0.3)
    assert pairs["underflows"] == -1 and pairs["uptime"] >= 0.0
    assert msg.types[::2] == "s" * (len(msg.args) // 2)


def test_status_reads_engine_stats_defensively(ctl, peer):
    class Stats:
        underflows = 3
        load_avg = 0.25

    ctl.engine.stats = Stats()
    handler = OscHandler(ctl, block_size=128)
    pairs = dict(handler.status_pairs())
    assert pairs["underflows"] == 3 and pairs["load"] == 0.25 and pairs["block_size"] == 128
    ctl.engine.stats = lambda: (_ for _ in ()).throw(RuntimeError("boom"))
    assert dict(handler.status_pairs())["underflows"] == -1


def test_ping_echoes_arguments(handler, peer):
    send(handler, peer, "/vibsynth/ping", 42, "x")
    (msg,) = peer.messages()
    assert (msg.address, msg.args) == ("/vibsynth/pong", (42, "x"))


def test_sync_without_worker(handler, peer):
    send(handler, peer, "/vibsynth/intensity", 0.1)
    send(handler, peer, "/vibsynth/sync", 7)
    assert [(m.address, m.args) for m in peer.messages()] == [("/vibsynth/synced", (7,))]


def test_sync_waits_for_engine():
    ctl = make_controller(2, auto_apply=False)
    peer = FakePeer()
    handler = OscHandler(ctl)
    worker = SyncWorker(ctl, handler.reply_synced, timeout_s=30.0)
    handler.sync_worker = worker
    worker.start()
    try:
        send(handler, peer, "/vibsynth/intensity", 0.1)
        send(handler, peer, "/vibsynth/sync", 9)
        assert peer.sent == []  # the engine has not applied the command: no reply yet
        ctl.engine.apply_all()
        assert peer.event.wait(10.0)
        assert [(m.address, m.args) for m in peer.messages()] == [("/vibsynth/synced", (9,))]
    finally:
        worker.stop()


def test_sync_answers_at_once_when_applied(ctl, peer):
    handler = OscHandler(ctl)
    handler.sync_worker = SyncWorker(ctl, handler.reply_synced)  # not started: must not be needed
    send(handler, peer, "/vibsynth/sync", 3)
    assert peer.messages()[0].args == (3,)


def test_learn_unavailable_and_hook(ctl, peer, monkeypatch):
    handler = OscHandler(ctl)
    monkeypatch.setattr(osc_handler, "_midi_learn_hook", lambda: None)
    send(handler, peer, "/vibsynth/learn", "balance")
    assert peer.errors() == [("/vibsynth/learn", "MIDI learn unavailable (no MIDI input is running)")]
    peer.clear()
    learned = []
    ctl.learn = learned.append  # a controller that offers learn
    send(handler, peer, "/vibsynth/learn", "balance")
    assert learned == ["balance"] and peer.messages()[0].args == ("/vibsynth/learn", "balance")


# ---------------------------------------------------------------------- notify
def test_notify_snapshot_coalescing_rate_limit(ctl, peer):
    now = [100.0]
    notifier = Notifier(ctl, "/vibsynth", rate_hz=10.0, clock=lambda: now[0])
    unsubscribe = ctl.subscribe(notifier.on_event)
    handler = OscHandler(ctl, notifier=notifier)
    send(handler, peer, "/vibsynth/notify", 1)
    assert peer.messages()[0].args == ("/vibsynth/notify", 1)
    peer.clear()
    notifier.pump()
    snapshot = {(m.address, m.args) for m in peer.messages()}
    assert ("/vibsynth/ch/4/intensity", (0.0,)) in snapshot and len(snapshot) == 16
    peer.clear()
    for value in (0.1, 0.2, 0.3):
        ctl.set_knob("intensity", value, channels=[1], source="midi")
    notifier.pump()
    assert peer.sent == []  # within 1/rate of the last push
    now[0] += 0.1
    notifier.pump()
    assert [(m.address, m.args) for m in peer.messages()] == [("/vibsynth/ch/2/intensity", (pytest.approx(0.3),))]
    peer.clear()
    send(handler, peer, "/vibsynth/notify", 0)
    peer.clear()
    ctl.set_knob("balance", 1.0)
    now[0] += 1.0
    notifier.pump()
    assert peer.sent == []
    unsubscribe()


def test_notify_unavailable_without_notifier(handler, peer):
    send(handler, peer, "/vibsynth/notify", 1)
    assert "not available" in peer.errors()[0][1]


# ---------------------------------------------------------------------- bundles
def test_immediate_bundle_applies_now(handler, ctl, peer):
    data = encode_bundle(
        IMMEDIATE, [encode_message("/vibsynth/intensity", (0.5,)), encode_message("/vibsynth/ch/1/balance", (1.0,))]
    )
    handler.handle_packet(data, peer)
    assert [c.at_frame for c in ctl.engine.commands] == [None, None]
    assert ctl.get("balance", 0) == 1.0 and handler.stats.bundles == 1


def test_future_bundle_is_scheduled_on_stream_clock(handler, ctl, peer):
    fs = ctl.engine.fs
    frame0 = ctl.engine.frame
    handler.clock.sample()  # reference: stream frame0 now
    when = time.time() + 2.0
    handler.handle_packet(encode_bundle(unix_to_ntp(when), [encode_message("/vibsynth/intensity", (0.5,))]), peer)
    (command,) = ctl.engine.commands
    assert command.at_frame == pytest.approx(frame0 + 2.0 * fs, abs=0.05 * fs)
    assert handler.stats.scheduled == 1 and peer.sent == []


def test_past_timetag_applies_now(handler, ctl, peer):
    data = encode_bundle(unix_to_ntp(time.time() - 5.0), [encode_message("/vibsynth/intensity", (0.5,))])
    handler.handle_packet(data, peer)
    assert ctl.engine.commands[0].at_frame is None


def test_bundle_beyond_horizon_rejected(handler, ctl, peer):
    data = encode_bundle(
        unix_to_ntp(time.time() + 3600.0),
        [encode_message("/vibsynth/intensity", (0.5,)), encode_message("/vibsynth/balance", (1.0,))],
    )
    handler.handle_packet(data, peer)
    assert ctl.engine.commands == [] and ctl.get("intensity", 0) == 0.0
    errors = peer.errors()
    assert [e[0] for e in errors] == ["/vibsynth/intensity", "/vibsynth/balance"]
    assert "horizon" in errors[0][1] and ctl.error_counts["osc.horizon"] == 2


def test_nested_bundle_timetags(handler, ctl, peer):
    handler.clock.sample()
    when = time.time() + 1.0
    inner = encode_bundle(unix_to_ntp(when), [encode_message("/vibsynth/balance", (0.5,))])
    outer = encode_bundle(IMMEDIATE, [encode_message("/vibsynth/intensity", (0.5,)), inner])
    handler.handle_packet(outer, peer)
    first, second = ctl.engine.commands
    assert first.at_frame is None and second.at_frame > ctl.engine.frame


class _Stream:
    """An engine's stream position (``frame_position``) at 1 kHz and the wall clock, both set by a test."""

    fs = 1000.0

    def __init__(self) -> None:
        self.frame_position, self.wall = 0, 10.0
        self.clock = StreamClock(self, wall=lambda: self.wall)

    def at(self, frame: int, wall: float) -> StreamClock:
        self.frame_position, self.wall = frame, wall
        return self.clock


def test_stream_clock_keeps_least_late_offset():
    stream = _Stream()
    stream.at(1000, 11.0).sample()  # exact
    frame, current = stream.at(1000, 11.09).frame_at(12.0)  # block not yet rendered: looks late
    assert frame == pytest.approx(2000, abs=1) and current == 1000
    assert stream.at(0, 20.0).frame_at(21.0)[0] == pytest.approx(1000, abs=1)  # the stream restarted


def test_stream_clock_forgets_samples_taken_before_the_stream_started():
    """Packets that arrive before the first block (a slow stream start) must not make timetags late.

    Frame 0 plays when the stream starts, not when the packet came: such a sample's offset is too
    large by the wait, and the least-late rule kept it (e2e: every timetag 0.1-0.3 s late).
    """
    stream = _Stream()
    stream.at(0, 10.0).sample()  # serve answers OSC; its stream starts 0.1 s later (less than a restart's jump)
    stream.at(0, 10.05).sample()
    assert stream.at(200, 10.3).frame_at(11.1)[0] == pytest.approx(1000, abs=1)  # frame 0 played at 10.1
    assert stream.at(300, 10.4).frame_at(11.4)[0] == pytest.approx(1300, abs=1)


# ---------------------------------------------------------------------- adapter contract
def test_add_arguments_and_create():
    parser = argparse.ArgumentParser()
    osc_adapter.add_arguments(parser)
    args = parser.parse_args(["--osc-port", "0", "--osc-host", "127.0.0.1"])
    server = osc_adapter.create(load_config().settings, args, make_controller(2), None)
    assert server is not None and server.name == "osc"
    server.start()
    try:
        assert server.port > 0 and "udp://127.0.0.1:" in server.describe()
    finally:
        server.stop()
    assert osc_adapter.create(load_config().settings, parser.parse_args(["--no-osc"]), make_controller(2), None) is None


@pytest.mark.parametrize(
    "overrides",
    [
        {"osc": {"port": 70000}},
        {"osc": {"schedule_horizon_s": -1}},
        {"osc": {"notify_rate_hz": 0}},
        {"osc": {"prefix": "no-slash"}},
        {"speed": {"curve": [[5, 0.2], [1, 0.3]]}},
    ],
)
def test_bad_osc_settings_are_refused_where_the_config_is_loaded(overrides):
    """The adapter takes the typed settings: a bad value never reaches it (the loader refuses it)."""
    with pytest.raises(ConfigError, match=r"command line: (osc|speed)\."):
        load_config(overrides=overrides, env={}, user_file=False)


def test_port_in_use_is_a_clear_error():
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind(("127.0.0.1", 0))
    try:
        server = OscServer(make_controller(1), port=blocker.getsockname()[1])
        with pytest.raises(ConfigError, match="cannot listen"):
            server.start()
    finally:
        blocker.close()


# ---------------------------------------------------------------------- transports
def test_slip_round_trip_and_oversize():
    payload = bytes(range(256)) * 3
    decoder = SlipDecoder(max_frame=1024)
    frames = decoder.feed(slip_encode(payload)[:100]) + decoder.feed(slip_encode(payload)[100:])
    assert frames == [payload]
    assert decoder.feed(slip_encode(b"x" * 2000) + slip_encode(b"ok")) == [b"ok"] and decoder.oversized == 1


def _udp_client(timeout=5.0):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(timeout)
    return sock


def test_udp_server_replies_to_sender():
    ctl = make_controller(2)
    server = OscServer(ctl, port=0)
    server.start()
    client = _udp_client()
    try:
        client.sendto(encode_message("/vibsynth/ch/2/intensity", (0.5,)), ("127.0.0.1", server.port))
        client.sendto(encode_message("/vibsynth/sync", (1,)), ("127.0.0.1", server.port))
        reply = decode_packet(client.recvfrom(65536)[0])
        assert (reply.address, reply.args) == ("/vibsynth/synced", (1,))
        assert ctl.get("intensity", 1) == 0.5
        assert server.udp.rcvbuf > 0
    finally:
        client.close()
        server.stop()


def test_udp_allow_list_drops_others():
    ctl = make_controller(1)
    server = OscServer(ctl, port=0, allow=["127.0.0.2"])
    server.start()
    client = _udp_client(timeout=0.5)
    try:
        client.sendto(encode_message("/vibsynth/ping"), ("127.0.0.1", server.port))
        with pytest.raises(socket.timeout):
            client.recvfrom(65536)
        assert server.counters()["denied"] == 1 and ctl.engine.commands == []
    finally:
        client.close()
        server.stop()


def test_tcp_slip_transport():
    ctl = make_controller(1)
    server = OscServer(ctl, port=0, tcp=True)
    server.start()
    conn = socket.create_connection(("127.0.0.1", server.port), timeout=5.0)
    try:
        conn.sendall(
            slip_encode(encode_message("/vibsynth/intensity", (0.25,)))
            + slip_encode(encode_message("/vibsynth/ping", (5,)))
        )
        decoder = SlipDecoder()
        frames: list[bytes] = []
        while not frames:
            frames = decoder.feed(conn.recv(4096))
        assert decode_packet(frames[0]).address == "/vibsynth/pong"
        assert ctl.get("intensity", 0) == 0.25
    finally:
        conn.close()
        server.stop()


# ---------------------------------------------------------------------- batches
def _batch(peer, *messages):
    return [(encode_message(address, args), peer) for address, *args in messages]


def test_batch_coalesces_to_the_last_move(handler, ctl, peer):
    handler.handle_batch(
        _batch(
            peer,
            *[("/vibsynth/ch/1/intensity", k / 10) for k in range(10)],
            ("/vibsynth/ch/1/balance", 1.0),
            ("/vibsynth/ch/1/balance", 2.0),
        )
    )
    assert [(c.name, c.value) for c in ctl.engine.commands] == [("intensity", pytest.approx(0.9)), ("balance", 2.0)]
    assert handler.stats.messages == 12


def test_batch_result_equals_sequential_application(rng, peer):
    knobs = [
        "/vibsynth/intensity",
        "/vibsynth/ch/1/intensity",
        "/vibsynth/ch/{1,2}/intensity",
        "/vibsynth/ch/2/texture",
        "/vibsynth/texture",
        "/vibsynth/ch/3/speed",
        "/vibsynth/balance",
    ]
    for _ in range(50):
        messages = []
        for _ in range(int(rng.integers(1, 12))):
            address = knobs[int(rng.integers(len(knobs)))]
            if address.endswith("texture"):
                messages.append((address, float(rng.uniform(0, 1)), float(rng.uniform(-2, 2))))
            elif address.endswith("speed"):
                messages.append((address, float(rng.uniform(0, 400))))
            else:
                messages.append((address, float(rng.uniform(0, 1))))
        sequential, batched = make_controller(4), make_controller(4)
        for data, p in _batch(peer, *messages):
            OscHandler(sequential).handle_packet(data, p)
        OscHandler(batched).handle_batch(_batch(peer, *messages))
        assert batched.state() == sequential.state()
        assert len(batched.engine.commands) <= len(sequential.engine.commands)


def test_batch_flushes_before_queries_and_replies_errors(handler, ctl, peer):
    handler.handle_batch(
        _batch(
            peer,
            ("/vibsynth/ch/2/intensity", 0.25),
            ("/vibsynth/ch/2/get", "intensity"),
            ("/vibsynth/ch/2/intensity", 7.0),
            ("/vibsynth/ch/2/intensity", 0.5),
        )
    )
    got = [(m.address, m.args) for m in peer.messages()]
    assert got[0] == ("/vibsynth/ch/2/intensity", (0.25,))
    assert got[1][0] == "/vibsynth/error" and "outside the allowed range" in got[1][1][1]
    assert ctl.get("intensity", 1) == 0.5


# ---------------------------------------------------------------------- vibsynth send
def test_send_type_inference_and_forcing():
    from vibsynth.cli.send import convert

    assert convert(["1", "0.5", "-2", "wood", "1e3", "99999999999"], None) == (
        [1, 0.5, -2, "wood", 1000.0, 99999999999.0],
        "ifisff",
    )
    assert convert(["3", "0.5"], "sd") == (["3", 0.5], "sd")
    assert convert(["7"], ",Ti") == ([7], "Ti")
    with pytest.raises(ParameterError):
        convert(["1"], "ff")
    with pytest.raises(ParameterError):
        convert(["x"], "i")


def test_send_command_prints_replies(capsys):
    from vibsynth.cli import main

    ctl = make_controller(2)
    server = OscServer(ctl, port=0)
    server.start()
    try:
        port = str(server.port)
        assert main(["send", "/vibsynth/ch/2/intensity", "0.5", "--port", port]) == 0
        assert main(["send", "/vibsynth/ch/2/get", "intensity", "--port", port, "--wait-reply", "5"]) == 0
        assert capsys.readouterr().out.strip() == "/vibsynth/ch/2/intensity f 0.5"
        assert main(["send", "/vibsynth/intensity", "nan", "--port", port, "--wait-reply", "5"]) == 1
        assert "finite" in capsys.readouterr().out
        assert main(["send", "/vibsynth/intensity", "0.25", "--delay", "0", "--port", port]) == 0
        assert main(["send", "/vibsynth/sync", "3", "--port", port, "--wait-reply", "5"]) == 0
        assert capsys.readouterr().out.strip() == "/vibsynth/synced i 3"
        assert ctl.get("intensity", 0) == 0.25
    finally:
        server.stop()


def test_send_rejects_bad_address():
    from vibsynth.cli import main

    assert main(["send", "vibsynth/intensity", "0.5", "--port", "9"]) == 2


def test_notify_over_udp_pushes_changes_from_other_sources():
    ctl = make_controller(1)
    server = OscServer(ctl, port=0, notify_rate_hz=50.0)
    server.start()
    client = _udp_client()
    try:
        client.sendto(encode_message("/vibsynth/notify", (1,)), ("127.0.0.1", server.port))
        seen: dict[str, tuple] = {}
        while "/vibsynth/done" not in seen or "/vibsynth/ch/1/intensity" not in seen:
            packet = decode_packet(client.recvfrom(65536)[0])
            for msg in packet.elements if isinstance(packet, Bundle) else (packet,):
                seen[msg.address] = msg.args
        assert seen["/vibsynth/ch/1/intensity"] == (0.0,)
        ctl.set_knob("intensity", 0.75, source="midi")  # not OSC: still pushed
        while True:
            msg = decode_packet(client.recvfrom(65536)[0])
            if isinstance(msg, Message) and msg.address == "/vibsynth/ch/1/intensity":
                break
        assert msg.args == (0.75,)
    finally:
        client.close()
        server.stop()


def test_notify_reports_a_layer_taking_a_channel_over(ctl, peer):
    now = [100.0]
    notifier = Notifier(ctl, "/vibsynth", rate_hz=10.0, clock=lambda: now[0])
    unsubscribe = ctl.subscribe(notifier.on_event)
    send(OscHandler(ctl, notifier=notifier), peer, "/vibsynth/notify", 1)
    notifier.pump()
    peer.clear()
    now[0] += 1.0
    ctl.drive("clip", channels=[2], intensity=0.7, source="clip")
    notifier.pump()
    pushed = sorted((m.address, m.args) for m in peer.messages())
    assert pushed == [("/vibsynth/ch/3/driver", ("clip",)), ("/vibsynth/ch/3/intensity", (pytest.approx(0.7),))]
    unsubscribe()
