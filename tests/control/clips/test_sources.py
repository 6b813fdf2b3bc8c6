"""Clips on the spatial touch sources: the clip moves the source's texture, the mixer spreads it."""

from __future__ import annotations

import pytest

from tests.control.clips.helpers import make_clip
from tests.control.osc.fakes import FakePeer, make_controller
from tests.control.spatial.rig import Clock, make_mixer
from vibsynth.control import clips, spatial
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.tables import register_tables
from vibsynth.errors import VibsynthError

RAMP = make_clip([(0, 0.2, -1.0), (200, 0.8, 1.0), (400, 0.8, 1.0)], duration_ms=400, name="ramp")
STEP_FRAMES = 480  # the mixer's 10 ms update at 48 kHz


class Rig:
    """A controller on a fake engine, a mixer on four actuators in a line, the clip player; the test drives time."""

    def __init__(self, basis) -> None:
        self.controller = make_controller(channels=4)
        self.engine = self.controller.engine
        self.clock = Clock()
        self.mixer = make_mixer(self.controller, basis, clock=self.clock)
        self.mixer.schedule_capacity = 1024
        spatial.attach(self.controller, self.mixer)
        self.player = ClipPlayer(self.controller, lambda name: RAMP, start_margin_frames=0)
        clips.attach(self.controller, self.player)

        def place(table, t):
            table.set_texture(0, 0.3, 0.0)
            table.set_position(0, (0.2, 0.0, 0.0), t)
            table.set_on(0, True, t)

        self.mixer.apply(place)
        self.run(STEP_FRAMES * 5)

    def run(self, frames: int) -> None:
        end = self.engine.frame + frames
        while self.engine.frame < end:
            self.player.tick()
            self.mixer.step()
            self.engine.frame += STEP_FRAMES // 2
            self.clock.advance(STEP_FRAMES / 2 / self.engine.fs)

    def texture(self) -> tuple[float, float]:
        return self.mixer.read(lambda table, now: (table.view(0, now).intensity, table.view(0, now).balance))

    def close(self) -> None:
        clips.detach(self.controller, self.player)
        spatial.detach(self.controller, self.mixer)


@pytest.fixture
def rig(basis):
    r = Rig(basis)
    yield r
    r.close()


def test_a_clip_moves_the_sources_texture_and_it_comes_back(rig):
    start = rig.engine.frame + STEP_FRAMES
    rig.player.play_source("ramp", sources=[0], at_frame=start)
    rig.run(STEP_FRAMES)
    seen = []
    while rig.engine.frame < start + int(0.4 * rig.engine.fs):
        rig.run(STEP_FRAMES)
        u_ms = 1000.0 * (rig.engine.frame - start) / rig.engine.fs
        want = RAMP.value_at(u_ms)
        seen.append((rig.texture(), want))
        assert rig.texture()[0] == pytest.approx(want[0], abs=0.6 / 200 * 10 * 1.5)  # within an update's slope
    assert rig.player.sources.names() == {0: "ramp"}
    assert max(t[0] for t, _ in seen) == pytest.approx(0.8)
    driven = rig.mixer.driven()
    assert 2 in driven and driven[2][0] == pytest.approx(0.8, abs=1e-6)  # the actuator under the source
    rig.run(STEP_FRAMES * 6)
    assert rig.texture() == pytest.approx((0.3, 0.0)) and rig.player.sources.names() == {}


def test_stop_and_a_new_play_leave_no_stale_sample(rig):
    rig.player.play_source("ramp", sources=[0], at_frame=rig.engine.frame)
    rig.run(STEP_FRAMES * 5)
    assert rig.texture() != (0.3, 0.0)
    assert rig.player.stop_source(sources=[0]) == 1
    rig.run(STEP_FRAMES * 20)  # samples already handed to the mixer are no-ops now
    assert rig.texture() == pytest.approx((0.3, 0.0))


def test_source_play_over_osc_and_without_a_layout(rig, basis):
    handler = register_tables(OscHandler(rig.controller, sync_worker=None))
    peer = FakePeer()
    handler.handle_packet(encode_message("/vibsynth/source/1/play", ("ramp", 1.0, 2.0), "sff"), peer)
    assert peer.errors() == [] and rig.player.sources.names() == {0: "ramp"}
    status = dict(handler.status_pairs())
    assert status["source1.clip"] == "ramp" and status["clips_playing"] == 0  # (channels: none)
    handler.handle_packet(encode_message("/vibsynth/source/1/stop", (20.0,), "f"), peer)
    assert peer.errors() == [] and rig.player.sources.names() == {}
    handler.handle_packet(encode_message("/vibsynth/source/1/play", ("ramp", float("nan")), "sf"), peer)
    assert "gain must be a finite number" in peer.errors()[-1][1]
    spatial.detach(rig.controller, rig.mixer)
    with pytest.raises(VibsynthError, match="sources need a layout"):
        rig.player.play_source("ramp", sources=[0])
    handler.handle_packet(encode_message("/vibsynth/source/1/play", ("ramp",), "s"), peer)
    assert "sources need a layout" in peer.errors()[-1][1]
