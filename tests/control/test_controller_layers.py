"""Controller layers: knobs < follow < sources < clip, with the real engine enforcing the same order."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.control.controller import Controller, KnobEvent
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.commands import LAYER_NAMES
from vibsynth.engine.engine import Engine
from vibsynth.errors import ParameterError
from vibsynth.formats.basis_file import default_basis


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=16000.0, loop_seconds=1.0, levels=9, seed=2))


@pytest.fixture
def rig(bank):
    engine = Engine(bank, channels=3, glide_s=0.0, max_block=256)
    controller = Controller(engine, initial_glide_s=0.0)
    events: list[KnobEvent] = []
    controller.subscribe(events.append)
    return engine, controller, events


def plays(engine: Engine, channel: int) -> tuple[float, float]:
    k, b, _ = engine.knob_values()[channel]
    return k, b


def test_a_clip_takes_a_channel_over_and_direct_knobs_wait_for_its_release(rig):
    engine, ctl, events = rig
    ctl.set_texture(0.3, 0.5)
    ctl.drive("clip", channels=[1], intensity=0.9, balance=-1.0, source="clip")
    ctl.set_knob("intensity", 0.6, source="osc")  # every channel; channel 1 remembers it
    engine.render(512)
    assert plays(engine, 0) == pytest.approx((0.6, 0.5))
    assert plays(engine, 1) == pytest.approx((0.9, -1.0))
    assert ctl.get("texture", 1) == pytest.approx((0.9, -1.0))
    assert ctl.get("driver", 1) == "clip" and ctl.driver(0) == "knobs"
    assert ctl.layer_targets("knobs", 1) == pytest.approx((0.6, 0.5))
    ctl.release("clip", channels=[1], glide_s=0.0, source="clip")
    engine.render(512)
    assert plays(engine, 1) == pytest.approx((0.6, 0.5))
    assert ctl.get("texture", 1) == pytest.approx((0.6, 0.5))
    drivers = [(e.channel, e.value) for e in events if e.name == "driver"]
    assert drivers == [(1, "clip"), (1, "knobs")]


def test_the_fast_path_shape_of_knob_move_is_held_back_too(rig):
    """The OSC fast path pushes layer-0 moves straight into the core and records them afterwards."""
    engine, ctl, _ = rig
    ctl.drive("sources", channels=[0, 1, 2], intensity=0.4, balance=0.0)
    seq = engine._core.push(1, 0, 0.8, float("nan"), (1 << 64) - 1, -1)
    ctl.record([("intensity", c, 0.8) for c in range(3)], seq, source="osc")
    engine.render(256)
    assert [plays(engine, c)[0] for c in range(3)] == pytest.approx([0.4] * 3)
    assert ctl.get("intensity", 2) == pytest.approx(0.4)
    ctl.release("sources", channels=[2], glide_s=0.0)
    engine.render(256)
    assert plays(engine, 2)[0] == pytest.approx(0.8)


def test_clip_over_sources_over_knobs_and_back_down(rig):
    engine, ctl, _ = rig
    ctl.set_texture(0.2, 0.0, channels=[0])
    ctl.drive("sources", channels=[0], intensity=0.5, balance=1.0)
    ctl.drive("clip", channels=[0], intensity=0.7)  # balance: what the channel played (1.0)
    ctl.drive("sources", channels=[0], intensity=0.55, balance=1.5)  # kept under the clip
    engine.render(256)
    assert plays(engine, 0) == pytest.approx((0.7, 1.0))
    ctl.release("clip", channels=[0], glide_s=0.0)
    engine.render(256)
    assert plays(engine, 0) == pytest.approx((0.55, 1.5))
    assert ctl.driver(0) == "sources"
    ctl.release("sources", channels=[0], glide_s=0.0)
    engine.render(256)
    assert plays(engine, 0) == pytest.approx((0.2, 0.0))
    assert ctl.driver(0) == "knobs"


def test_timetagged_clip_moves_land_on_their_frames_and_cancel_drops_the_rest(rig):
    engine, ctl, _ = rig
    start = engine.frame_position + 1000
    ctl.drive("clip", channels=[2], intensity=0.1, balance=0.0, at_frame=start, glide_s=0.0)
    for k in range(1, 5):
        ctl.drive("clip", channels=[2], intensity=0.1 + 0.2 * k, at_frame=start + 500 * k, glide_s=0.0)
    out = []
    out.append(engine.render(start - engine.frame_position + 10))
    assert plays(engine, 2)[0] == pytest.approx(0.1)
    engine.render(600)
    assert plays(engine, 2)[0] == pytest.approx(0.3)
    ctl.cancel_scheduled("clip", channels=[2])
    ctl.release("clip", channels=[2], glide_s=0.0)
    engine.render(3000)
    assert plays(engine, 2)[0] == pytest.approx(0.0)  # the knob target (never set)
    assert engine.stats.pending == 0


def test_panic_hands_everything_back_to_the_knobs_and_tells_the_drivers(rig):
    engine, ctl, _ = rig
    told = []
    ctl.on_panic(lambda: told.append(True))
    ctl.drive("clip", channels=[0, 1], intensity=0.8)
    ctl.drive("sources", intensity=0.6)
    ctl.panic()
    ctl.set_knob("intensity", 0.25)
    engine.render(2000)
    assert told == [True]
    assert [plays(engine, c)[0] for c in range(3)] == pytest.approx([0.25] * 3)
    assert [ctl.driver(c) for c in range(3)] == ["knobs"] * 3
    assert ctl.layer_targets("clip", 0) is None


def test_layer_arguments_are_validated_and_nothing_changes(rig):
    engine, ctl, _ = rig
    with pytest.raises(ParameterError, match="unknown layer"):
        ctl.drive("lasers", intensity=0.5)
    with pytest.raises(ParameterError, match="base layer"):
        ctl.drive("knobs", intensity=0.5)
    with pytest.raises(ParameterError, match="intensity"):
        ctl.drive("clip", intensity=float("nan"))
    with pytest.raises(ParameterError, match="balance"):
        ctl.drive("clip", balance=99.0)
    with pytest.raises(ParameterError, match="channel"):
        ctl.drive("clip", channels=[7], intensity=0.5)
    assert [ctl.driver(c) for c in range(3)] == ["knobs"] * 3
    assert engine.stats.pending == 0


def test_random_layer_traffic_keeps_controller_and_engine_in_agreement(rig):
    engine, ctl, _ = rig
    rng = np.random.default_rng(11)
    for _ in range(300):
        op = rng.integers(5)
        chans = sorted(set(rng.integers(0, 3, size=rng.integers(1, 4)).tolist()))
        value = float(rng.uniform(0, 1))
        if op == 0:
            ctl.set_knob("intensity", value, channels=chans)
        elif op in (1, 2):
            ctl.drive(("follow", "sources", "clip")[int(rng.integers(3))], channels=chans, intensity=value, glide_s=0.0)
        elif op == 3:
            ctl.release(("follow", "sources", "clip")[int(rng.integers(3))], channels=chans, glide_s=0.0)
        else:
            ctl.set_knob("balance", float(rng.uniform(-2, 2)), channels=chans)
        engine.render(int(rng.integers(1, 300)))
    engine.render(10)
    for c in range(3):
        assert plays(engine, c) == pytest.approx(ctl.get("texture", c), abs=1e-9)
        assert engine.layers()[c] == LAYER_NAMES.index(ctl.driver(c))
