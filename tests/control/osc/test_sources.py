"""OSC ``/vibsynth/source/{k}/...``: every method, its replies, bundles, patterns and the attacks."""

from __future__ import annotations

import math
import time

import pytest

from tests.control.osc.fakes import send
from tests.control.spatial.rig import Clock, make_mixer
from vibsynth.control import spatial
from vibsynth.control.osc.codec import encode_bundle, encode_message, unix_to_ntp
from vibsynth.control.osc.sources import NO_LAYOUT


@pytest.fixture
def clock():
    return Clock()


@pytest.fixture
def mixer(ctl, basis, clock):
    mixer = make_mixer(ctl, basis, clock=clock)
    spatial.attach(ctl, mixer)  # findable, stepped by hand (no thread)
    yield mixer
    spatial.detach(ctl, mixer)


def view(mixer, k):
    return mixer.read(lambda table, now: table.view(k - 1, now))


def replies(peer):
    return [(m.address, m.types, m.args) for m in peer.messages()]


def test_without_a_layout_every_source_message_says_why(handler, peer, ctl):
    send(handler, peer, "/vibsynth/source/1/pos", 0.1, 0.2)
    assert peer.errors() == [("/vibsynth/source/1/pos", NO_LAYOUT)]
    assert ctl.error_counts == {"osc.error": 1}


def test_setters_and_get_replies_in_setter_form(handler, peer, mixer, clock):
    send(handler, peer, "/vibsynth/source/3/pos", 0.1, 0.2, 0.05)
    send(handler, peer, "/vibsynth/source/3/texture", 0.7, -1.5)
    send(handler, peer, "/vibsynth/source/3/radius", 0.2)
    send(handler, peer, "/vibsynth/source/3/rolloff", "phantom")
    send(handler, peer, "/vibsynth/source/3/on", 1)
    send(handler, peer, "/vibsynth/source/3/speed", 1)
    assert peer.errors() == []
    for name in ("pos", "texture", "radius", "rolloff", "on", "speed", "preset", "intensity", "balance"):
        send(handler, peer, "/vibsynth/source/3/get", name)
    got = {address.rsplit("/", 1)[1]: (types, args) for address, types, args in replies(peer)}
    assert got["pos"][0] == "fff" and got["pos"][1] == pytest.approx((0.1, 0.2, 0.05))
    assert got["texture"][0] == "ff" and got["texture"][1] == pytest.approx((0.7, -1.5))
    assert got["radius"][1] == pytest.approx((0.2,))
    assert got["rolloff"] == ("s", ("phantom",))
    assert got["on"] == ("i", (1,)) and got["speed"] == ("i", (1,))
    assert got["preset"] == ("s", ("",))
    assert got["intensity"][1] == pytest.approx((0.7,)) and got["balance"][1] == pytest.approx((-1.5,))
    assert all(address.startswith("/vibsynth/source/3/") for address, _, _ in replies(peer))


def test_intensity_balance_and_preset(handler, peer, mixer):
    send(handler, peer, "/vibsynth/source/1/intensity", 0.4)
    send(handler, peer, "/vibsynth/source/1/balance", 1.25)
    assert (view(mixer, 1).intensity, view(mixer, 1).balance) == pytest.approx((0.4, 1.25))
    send(handler, peer, "/vibsynth/source/1/preset", "silk")
    v = view(mixer, 1)
    assert (v.intensity, v.balance, v.preset) == (0.3, -1.0, "silk")
    send(handler, peer, "/vibsynth/source/1/preset", "velvet")
    assert "unknown preset 'velvet'" in peer.errors()[-1][1]
    assert view(mixer, 1).preset == "silk"


def test_a_channel_under_a_source_reports_what_it_plays(handler, peer, mixer, clock):
    send(handler, peer, "/vibsynth/ch/1/texture", 0.2, 0.5)
    send(handler, peer, "/vibsynth/source/1/texture", 0.9, -1.0)
    send(handler, peer, "/vibsynth/source/1/pos", 0.0, 0.0)
    send(handler, peer, "/vibsynth/source/1/on", 1)
    clock.advance(0.05)
    mixer.step()
    send(handler, peer, "/vibsynth/ch/1/get", "texture")
    assert replies(peer)[-1][0] == "/vibsynth/ch/1/texture"
    assert replies(peer)[-1][2] == pytest.approx((0.9, -1.0))
    send(handler, peer, "/vibsynth/source/1/on", 0)
    clock.advance(0.05)
    mixer.step()
    send(handler, peer, "/vibsynth/ch/1/get", "texture")
    assert replies(peer)[-1][2] == pytest.approx((0.2, 0.5))  # back to its direct knobs


@pytest.mark.parametrize(
    "address, args, fragment",
    [
        ("/vibsynth/source/1/pos", (math.nan, 0.0), "x must be a finite number"),
        ("/vibsynth/source/1/pos", (0.0, math.inf), "y must be a finite number"),
        ("/vibsynth/source/1/pos", (0.0, 0.0, -math.inf), "z must be a finite number"),
        ("/vibsynth/source/1/pos", (1e9, 0.0), "outside the allowed range [-10, 10]"),
        ("/vibsynth/source/1/pos", (0.1,), "pos: expects 2 or 3 argument(s)"),
        ("/vibsynth/source/1/pos", ("a", "b"), "x must be a number"),
        ("/vibsynth/source/0/pos", (0.0, 0.0), "source 0 out of range (sources are 1..16)"),
        ("/vibsynth/source/17/pos", (0.0, 0.0), "source 17 out of range (sources are 1..16)"),
        ("/vibsynth/source/99999999999999999999/on", (1,), "source 999999999999 out of range"),
        ("/vibsynth/source/1/radius", (1e30,), "radius (m) 1e+30 is outside the allowed range (0, 10]"),
        ("/vibsynth/source/1/radius", (0.0,), "outside the allowed range (0, 10]"),
        ("/vibsynth/source/1/radius", (-1.0,), "outside the allowed range (0, 10]"),
        ("/vibsynth/source/1/rolloff", ("cubic",), "unknown roll-off 'cubic'; choose one of linear, smooth"),
        ("/vibsynth/source/1/rolloff", (3,), "roll-off must be a string"),
        ("/vibsynth/source/1/texture", (1.5, 0.0), "intensity 1.5 is outside the allowed range [0, 1]"),
        ("/vibsynth/source/1/balance", (9.0,), "balance 9 is outside the allowed range [-3.5, 3.5]"),
        ("/vibsynth/source/1/on", (2,), "on must be 0 or 1"),
        ("/vibsynth/source/1/get", ("colour",), "unknown source setting 'colour'; known: pos, texture"),
        ("/vibsynth/source/1/rollof", ("linear",), "unknown address (did you mean .../rolloff?)"),
    ],
)
def test_attacks_get_one_clear_error_and_change_nothing(handler, peer, mixer, ctl, address, args, fragment):
    before = [view(mixer, k) for k in range(1, 17)]
    send(handler, peer, address, *args)
    assert len(peer.errors()) == 1
    assert peer.errors()[0][0] == address and fragment in peer.errors()[0][1], peer.errors()
    assert [view(mixer, k) for k in range(1, 17)] == before
    assert sum(ctl.error_counts.values()) == 1


def test_patterns_reach_several_sources_at_once(handler, peer, mixer):
    send(handler, peer, "/vibsynth/source/*/on", 1)
    assert all(view(mixer, k).on for k in range(1, 17))
    send(handler, peer, "/vibsynth/source/{2,4}/radius", 0.3)
    assert [view(mixer, k).radius for k in (1, 2, 3, 4)] == pytest.approx([0.1, 0.3, 0.1, 0.3])
    send(handler, peer, "/vibsynth/source/[1-3]/get", "on")
    assert [a for a, _, _ in replies(peer)] == [f"/vibsynth/source/{k}/on" for k in (1, 2, 3)]
    send(handler, peer, "/vibsynth/source/*/rolloff", "spiral")  # refused for every source, once
    assert len(peer.errors()) == 1 and all(view(mixer, k).rolloff == "linear" for k in range(1, 17))
    send(handler, peer, "/vibsynth/*/1/pos", 0.05, 0.0)  # only the sources have pos
    assert view(mixer, 1).target == pytest.approx((0.05, 0.0, 0.0)) and len(peer.errors()) == 1


def test_a_flood_of_positions_coalesces(handler, peer, mixer, ctl, clock):
    send(handler, peer, "/vibsynth/source/1/on", 1)
    packets = [(encode_message("/vibsynth/source/1/pos", (0.001 * (k % 300), 0.0)), peer) for k in range(20_000)]
    started = time.perf_counter()
    handler.handle_batch(packets)
    print(f"\n20000 position messages handled in {time.perf_counter() - started:.2f} s")
    assert peer.errors() == [] and mixer.pending == 0
    assert view(mixer, 1).target == pytest.approx((0.001 * (19_999 % 300), 0.0, 0.0))
    commands = len(ctl.engine.commands)
    clock.advance(0.05)
    mixer.step()
    assert mixer.mixes == 1 and len(ctl.engine.commands) - commands <= 12


def test_timetagged_bundles_schedule_source_messages(handler, peer, mixer, ctl, clock):
    engine = ctl.engine
    handler.clock.sample()
    bundle = encode_bundle(
        unix_to_ntp(time.time() + 0.5),
        [
            encode_message("/vibsynth/source/2/pos", (0.3, 0.0)),
            encode_message("/vibsynth/source/2/texture", (0.6, 0.5)),
            encode_message("/vibsynth/source/2/on", (1,)),
        ],
    )
    handler.handle_packet(bundle, peer)
    assert peer.errors() == [] and mixer.pending == 3
    assert not view(mixer, 2).on  # not yet
    frames = {update[0] for update in mixer._schedule}
    assert len(frames) == 1 and next(iter(frames)) > engine.frame  # one frame, in the future
    engine.frame = next(iter(frames))
    clock.advance(0.5)
    mixer.step()
    assert view(mixer, 2).on and view(mixer, 2).target == pytest.approx((0.3, 0.0, 0.0))
    assert list(mixer.driven()) == [3] and mixer.driven()[3] == pytest.approx((0.6, 0.5))


def test_a_full_source_schedule_answers_an_error(handler, peer, mixer, ctl):
    handler.clock.sample()
    for k in range(9):
        bundle = encode_bundle(
            unix_to_ntp(time.time() + 1.0 + k / 100), [encode_message("/vibsynth/source/1/intensity", (0.5,))]
        )
        handler.handle_packet(bundle, peer)
    assert mixer.pending == 8
    assert len(peer.errors()) == 1 and "8 timetagged source messages are already waiting" in peer.errors()[0][1]
    assert ctl.error_counts == {"osc.schedule_full": 1}
