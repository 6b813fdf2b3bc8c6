"""Follow over OSC: gain, gate, range, focus, per-channel on/off, getters in setter form, bad values, no follower."""

from __future__ import annotations

import pytest

from tests.control.follow.fakes import tone
from tests.control.osc.fakes import FakePeer, send
from vibsynth.control import follow
from vibsynth.control.osc.follow import NOT_RUNNING
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.tables import register_tables
from vibsynth.control.oscquery.methods import method_nodes, reads
from vibsynth.control.oscquery.tree import Tree
from vibsynth.settings.models import bounds_of

FS = 16000.0


@pytest.fixture
def osc(make_rig):
    rig = make_rig(channels=2, follow={"mode": "audio"})
    follow.attach(rig.controller, rig.follower)
    handler = register_tables(OscHandler(rig.controller, sync_worker=None))
    yield rig, handler, FakePeer()
    follow.detach(rig.controller, rig.follower)


def replies(peer: FakePeer) -> list[tuple[str, tuple]]:
    return [(m.address, tuple(m.args)) for m in peer.messages()]


def test_gain_gate_range_and_focus_are_set_and_read_back_in_setter_form(osc):
    rig, handler, peer = osc
    send(handler, peer, "/vibsynth/follow/gain", 4.5)
    send(handler, peer, "/vibsynth/follow/gate", -45.0)
    send(handler, peer, "/vibsynth/follow/range", 30.0)
    send(handler, peer, "/vibsynth/follow/focus", "effects")
    assert peer.errors() == []
    for name in ("gain", "gate", "range", "focus"):
        send(handler, peer, "/vibsynth/follow/get", name)
    assert replies(peer) == [
        ("/vibsynth/follow/gain", (4.5,)),
        ("/vibsynth/follow/gate", (-45.0,)),
        ("/vibsynth/follow/range", (30.0,)),
        ("/vibsynth/follow/focus", ("effects",)),
    ]
    rig.feed(tone(FS, 0.05, 0.01))  # the worker applies the new values at its next step
    view = rig.follower.routes()[0]
    assert view.focus == "effects" and rig.follower.routes()[0].mode == "audio"
    assert [r.tracker.params.gain_db for r in rig.follower._routes] == [4.5, 4.5]
    assert [r.tracker.params.gate_db for r in rig.follower._routes] == [-45.0, -45.0]
    assert [r.tracker.params.range_db for r in rig.follower._routes] == [30.0, 30.0]


def test_the_range_is_the_input_span_the_knob_covers(osc):
    """The range is what the tracker maps onto the knob (top - range -> 0, top -> 1): the same tone sits as
    many dB below the top in 60 dB as in 20 dB, so it reads lower on the knob in the narrower range."""
    rig, handler, peer = osc
    played = {}
    for range_db in (60.0, 20.0):
        send(handler, peer, "/vibsynth/follow/range", range_db)
        rig.feed(tone(FS, 0.6, 0.05))
        played[range_db] = rig.follower.routes()[0].intensity
    assert peer.errors() == []
    below_top = {r: (1.0 - played[r]) * r for r in played}
    assert 0.0 < played[20.0] < played[60.0] - 0.3
    assert below_top[20.0] == pytest.approx(below_top[60.0], abs=0.5)


@pytest.mark.parametrize(
    ("address", "value", "message", "kind"),
    [
        ("/vibsynth/follow/gain", 61.0, "outside the allowed range [-60, 60]", "osc.invalid_value"),
        ("/vibsynth/follow/gate", 3.0, "outside the allowed range [-200, 0]", "osc.invalid_value"),
        (
            "/vibsynth/follow/range",
            5.0,
            "range (dB) 5 is outside the allowed range [6, 120]",
            "osc.invalid_value",
        ),
        ("/vibsynth/follow/range", "wide", "must be a number", "osc.bad_arguments"),
        ("/vibsynth/follow/range", float("nan"), "range", "osc.invalid_value"),
        ("/vibsynth/follow/range", float("inf"), "range", "osc.invalid_value"),
        ("/vibsynth/follow/focus", "loud", "must be one of all, effects, bass, beat", "osc.invalid_value"),
        ("/vibsynth/follow/gain", "loud", "must be a number", "osc.bad_arguments"),
        ("/vibsynth/follow/get", "volume", "unknown follow setting 'volume'", "osc.invalid_value"),
        ("/vibsynth/ch/1/follow", 2, "must be 0 or 1", "osc.invalid_value"),
    ],
)
def test_bad_values_get_an_error_reply_are_counted_and_change_nothing(osc, address, value, message, kind):
    rig, handler, peer = osc
    send(handler, peer, address, value)
    [(where, text)] = peer.errors()
    assert where == address and message in text
    assert rig.controller.error_counts == {kind: 1}
    assert (rig.follower.gain_db, rig.follower.gate_db, rig.follower.range_db, rig.follower.focus) == (
        0.0,
        -60.0,
        rig.settings.follow.range_db,
        "all",
    )
    assert [rig.follower.is_on(c) for c in (0, 1)] == [True, True]


def test_the_oscquery_tree_lists_range_with_the_settings_bounds_and_its_live_value(osc):
    rig, handler, peer = osc
    tree = Tree(method_nodes(handler, lambda: [], lambda: []), reads(rig.controller), root_description="test")
    send(handler, peer, "/vibsynth/follow/range", 24.0)
    ctx = tree.context()
    node = tree.find("/vibsynth/follow/range").json(ctx)
    low, high = bounds_of("follow.range_db")
    assert node["TYPE"] == "f" and node["RANGE"] == [{"MIN": low, "MAX": high}] and node["VALUE"] == [24.0]
    assert "range" in tree.find("/vibsynth/follow/get").json(ctx)["RANGE"][0]["VALS"]


def test_follow_off_on_one_channel_gives_it_back_to_the_knobs_and_get_says_so(osc):
    rig, handler, peer = osc
    rig.feed(tone(FS, 0.3, 0.05))
    send(handler, peer, "/vibsynth/ch/2/follow", 0)
    send(handler, peer, "/vibsynth/ch/*/get", "follow")
    send(handler, peer, "/vibsynth/ch/2/get", "driver")
    assert replies(peer) == [
        ("/vibsynth/ch/1/follow", (1,)),
        ("/vibsynth/ch/2/follow", (0,)),
        ("/vibsynth/ch/2/driver", ("knobs",)),
    ]
    peer.clear()
    send(handler, peer, "/vibsynth/ch/*/follow", 1)
    send(handler, peer, "/vibsynth/get", "follow")
    assert replies(peer) == [("/vibsynth/ch/1/follow", (1,)), ("/vibsynth/ch/2/follow", (1,))]


def test_status_has_the_follow_keys(osc):
    rig, handler, peer = osc
    rig.feed(tone(FS, 0.3, 0.05))
    status = dict(handler.status_pairs())
    assert status["follow.device"] == "fake input (open)"
    assert status["follow.gate"] == 1 and status["follow.level_db"] > -60.0
    assert status["ch1.follow"] == 1 and status["ch2.follow"] == 1


def test_without_a_follower_every_follow_message_says_how_to_start_one(make_rig):
    rig = make_rig()
    handler = register_tables(OscHandler(rig.controller, sync_worker=None))
    peer = FakePeer()
    send(handler, peer, "/vibsynth/follow/gain", 1.0)
    send(handler, peer, "/vibsynth/ch/1/get", "follow")
    assert [text for _, text in peer.errors()] == [NOT_RUNNING, NOT_RUNNING]
    assert "follow.device" not in dict(handler.status_pairs())
