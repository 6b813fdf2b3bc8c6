"""The VRChat bridge on the OSC handler: avatar parameters through the codec (T/F, i, f) to sources,
channels, presets and clips; /avatar/change; unmapped parameters counted and dropped; bad values."""

from __future__ import annotations

import numpy as np
import pytest

from tests.control.clips.helpers import make_clip
from tests.control.osc.fakes import send
from tests.control.oscquery.test_tree import check_node
from tests.control.spatial.rig import Clock, make_mixer
from vibsynth.control import clips, spatial
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.osc.codec import encode_bundle, encode_message
from vibsynth.control.oscquery.methods import method_nodes, reads
from vibsynth.control.oscquery.tree import Tree
from vibsynth.control.vrchat.bridge import ROOT, VrchatBridge
from vibsynth.settings.models_vrchat import Vrchat

IMPACT = make_clip([(0, 0.9, 1.0), (100, 0.1, 0.0)], duration_ms=150, name="impact")

PARAMETERS = [
    {"name": "ChestL", "source": 1, "at": [0.1, 0.0], "preset": "sand", "drive": "level"},
    {"name": "Spine", "source": 2, "moving": [[0.0, 0.0], [0.3, 0.0]], "preset": "silk", "threshold": 0.05},
    {"name": "Rub", "channel": 3, "preset": "sand", "drive": "velocity"},
    {"name": "Hug", "channel": 4, "drive": "level"},
    {"name": "Slap", "clip": "impact", "channel": 2},
    {"name": "Wet", "preset": "silk", "threshold": 0.5},
]


@pytest.fixture
def clock():
    return Clock()


@pytest.fixture
def mixer(ctl, basis, clock):
    mixer = make_mixer(ctl, basis, clock=clock)
    spatial.attach(ctl, mixer)
    yield mixer
    spatial.detach(ctl, mixer)


@pytest.fixture
def player(ctl):
    player = ClipPlayer(ctl, lambda name: {"impact": IMPACT}[name], start_margin_frames=0)
    clips.attach(ctl, player)
    yield player
    clips.detach(ctl, player)


@pytest.fixture
def bridge(ctl, handler, mixer, player, clock):
    bridge = VrchatBridge(Vrchat(enabled=True, parameters=PARAMETERS, velocity_fade_ms=200.0), ctl, clock=clock)
    handler.register_namespace(ROOT, bridge)
    bridge.start()
    yield bridge
    bridge.stop()


def view(mixer, k):
    return mixer.read(lambda table, now: table.view(k - 1, now))


def param(handler, peer, name, *args, types=None):
    send(handler, peer, f"/avatar/parameters/{name}", *args, types=types)


def test_a_proximity_drives_a_source_at_its_point_and_holds(handler, peer, bridge, mixer, clock):
    param(handler, peer, "ChestL", 0.5)
    v = view(mixer, 1)
    assert v.on and v.target == pytest.approx((0.1, 0.0, 0.0))
    assert (v.intensity, v.balance) == pytest.approx((0.5 * 0.7, 1.5))  # sand: 0.7, 1.5
    clock.advance(5.0)
    bridge.tick()
    assert view(mixer, 1).intensity == pytest.approx(0.35) and view(mixer, 1).on  # no message: it holds
    param(handler, peer, "ChestL", 0.0)
    assert not view(mixer, 1).on
    assert peer.errors() == [] and bridge.stats.mapped == 2


def test_a_moving_touch_follows_its_value_along_the_path(handler, peer, bridge, mixer, clock):
    rng = np.random.default_rng(5)
    for value in np.sort(rng.uniform(0.06, 1.0, 10)):
        param(handler, peer, "Spine", float(value))
        v = view(mixer, 2)
        assert v.on and v.target == pytest.approx((0.3 * float(value), 0.0, 0.0), abs=1e-6)
        assert v.intensity == pytest.approx(0.3)  # silk's intensity (level drive of a moving touch)
        clock.advance(0.011)
    param(handler, peer, "Spine", 0.0)  # at or below the threshold: the touch ends
    assert not view(mixer, 2).on


def test_velocity_on_a_channel_rises_with_speed_and_fades_when_still(handler, peer, bridge, ctl, clock):
    for speed in (1.0, 3.0):  # proximity units per second (full = 4)
        bridge.reset()
        value = 0.0
        for _ in range(10):
            param(handler, peer, "Rub", value)
            value += speed / 90
            clock.advance(1 / 90)
        clock.advance(-1 / 90)
        assert ctl.state()[2].intensity == pytest.approx(0.7 * speed / 4.0, rel=1e-6)
        assert ctl.state()[2].balance == pytest.approx(min(1.5 + speed / 4.0, ctl.limits.balance_max))
    clock.advance(0.1)  # half the fade
    assert bridge.tick() and ctl.state()[2].intensity == pytest.approx(0.7 * 0.75 * 0.5, rel=1e-6)
    clock.advance(0.1001)
    assert not bridge.tick() and ctl.state()[2].intensity == 0.0


def test_a_level_channel_takes_the_value_as_intensity(handler, peer, bridge, ctl):
    param(handler, peer, "Hug", 0.8)
    assert ctl.state()[3].intensity == pytest.approx(0.8)  # no preset: intensity 1 x the value
    param(handler, peer, "Hug", 3, types="i")  # an int: clipped to 1
    assert ctl.state()[3].intensity == 1.0


def test_bools_rising_edge_plays_the_clip_once(handler, peer, bridge, player):
    param(handler, peer, "Slap", types="F")
    assert player.playing(1) is None
    param(handler, peer, "Slap", types="T")  # VRChat's bool: the T type tag, no data
    assert player.playing(1).name == "impact" and player.stats.plays == 1
    param(handler, peer, "Slap", types="T")  # held: no new edge
    assert player.stats.plays == 1 and player.playing(0) is None  # channel 2 only


def test_a_threshold_crossing_loads_a_preset(handler, peer, bridge, ctl):
    param(handler, peer, "Wet", 0.4)
    assert ctl.state()[0].preset is None
    param(handler, peer, "Wet", 0.6)
    assert all(s.preset == "silk" for s in ctl.state())


def test_avatar_change_resets_everything(handler, peer, bridge, mixer, ctl, player, clock):
    param(handler, peer, "ChestL", 0.9)
    param(handler, peer, "Hug", 0.9)
    param(handler, peer, "Slap", types="T")
    send(handler, peer, "/avatar/change", "avtr_0f1e2d3c-0000-4000-8000-000000000000")
    assert not view(mixer, 1).on and ctl.state()[3].intensity == 0.0 and player.playing(1) is None
    assert bridge.value("ChestL") == 0.0 and bridge.stats.avatar.startswith("avtr_")
    param(handler, peer, "Slap", types="T")  # a new edge after the reset
    assert player.stats.plays == 2 and peer.errors() == []


def test_values_read_from_vrchat_start_the_bridge_without_playing_or_stroking(
    handler, peer, bridge, mixer, ctl, player, clock
):
    changes = []
    bridge.on_avatar_change = lambda: changes.append(True)
    param(handler, peer, "Hug", 0.3)  # a message came first: newer than the tree's value
    read = {"ChestL": 0.5, "Hug": 0.9, "Slap": 1.0, "Rub": 0.4, "Wet": 1.0, "Grounded": 1.0}
    assert bridge.prime(read, "avtr_0f1e2d3c-0000-4000-8000-000000000001") == 4
    assert view(mixer, 1).on and view(mixer, 1).intensity == pytest.approx(0.35)  # a resting hand is felt
    assert ctl.state()[3].intensity == pytest.approx(0.3)  # the message's value stays
    assert player.playing(1) is None and player.stats.plays == 0  # a bool already true: no edge
    assert all(s.preset is None for s in ctl.state())  # nor a preset's threshold
    assert ctl.state()[2].intensity == 0.0  # a velocity drive starts still
    assert bridge.stats.primed == 4 and bridge.stats.avatar.endswith("0001") and bridge.stats.mapped == 1
    param(handler, peer, "Slap", types="F")
    param(handler, peer, "Slap", types="T")  # the next real edge plays
    assert player.stats.plays == 1
    send(handler, peer, "/avatar/change", "avtr_0f1e2d3c-0000-4000-8000-000000000002")
    assert changes == [True]  # the service reads the new avatar's values
    assert bridge.prime({"Hug": 0.7}) == 1 and ctl.state()[3].intensity == pytest.approx(0.7)


def test_unmapped_parameters_are_counted_and_cost_nothing_else(handler, peer, bridge, mixer, ctl):
    rng = np.random.default_rng(11)
    before = (ctl.state(), [view(mixer, k) for k in range(1, 17)], dict(ctl.error_counts), len(ctl.engine.commands))
    names = [f"Unknown{int(i)}" for i in rng.integers(0, 10**6, 10_000)]
    for i, name in enumerate(names):
        types = "fTFi"[i % 4]
        args = {"f": (float(rng.random()),), "T": (), "F": (), "i": (int(rng.integers(0, 255)),)}[types]
        param(handler, peer, name, *args, types=types)
    bundle = encode_bundle(1, [encode_message("/avatar/parameters/VelocityX", (0.3,)), encode_message("/avatar/x")])
    handler.handle_packet(bundle, peer)
    assert bridge.stats.unmapped == 10_002 and bridge.stats.mapped == 0
    assert peer.sent == []  # no error reply
    after = (ctl.state(), [view(mixer, k) for k in range(1, 17)], dict(ctl.error_counts), len(ctl.engine.commands))
    assert after == before
    assert dict(handler.status_pairs())["vrchat.unmapped"] == 10_002


@pytest.mark.parametrize(
    "args, types", [(("text",), "s"), ((), ""), ((0.1, 0.2), "ff"), ((float("nan"),), "f"), ((b"\x00",), "b")]
)
def test_bad_values_of_a_mapped_parameter_are_counted_and_change_nothing(handler, peer, bridge, ctl, args, types):
    before = ctl.state()
    param(handler, peer, "Hug", *args, types=types)
    assert ctl.state() == before and bridge.stats.bad_values == 1
    assert ctl.error_counts == {"vrchat.bad_value": 1} and peer.sent == []


def test_the_oscquery_tree_has_avatar_so_vrchat_sends_to_us(handler, ctl, bridge, peer):
    tree = Tree(method_nodes(handler, lambda: [], lambda: []), reads(ctl))
    tree.register(bridge)
    events = tree.refresh()
    assert ("PATH_ADDED", "/avatar/change") in events and tree.find("/avatar") is not None
    check_node(tree.find("/avatar").json(tree.context()))  # the proposal's attribute rules, every /avatar node
    param(handler, peer, "Hug", 0.25)
    assert tree.value("/avatar/parameters/Hug", tree.context()) == ("f", [0.25])


def test_namespace_roots_cannot_overlap_the_address_space(handler, bridge):
    for root in ("/vibsynth/", "/avatar/", "/avatar/parameters/", "avatar", "/"):
        with pytest.raises(Exception, match="namespace root"):
            handler.register_namespace(root, bridge)
