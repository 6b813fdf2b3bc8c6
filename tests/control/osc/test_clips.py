"""OSC play/stop/get clip on a real Controller and Engine, with the shipped clips; attacks on every argument."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.control.osc.fakes import FakePeer
from vibsynth.control import clips
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.controller import Controller
from vibsynth.control.osc.codec import encode_bundle, encode_message, unix_to_ntp
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.tables import register_tables
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis
from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir

FS = 8000.0
BLOCK = 64


@pytest.fixture(scope="module")
def bank():
    return build_bank(default_basis(), BankSpec(fs=FS, loop_seconds=1.0, levels=15, seed=4))


@pytest.fixture
def rig(bank, tmp_path):
    engine = Engine(bank, channels=2, glide_s=0.0, max_block=BLOCK)
    controller = Controller(engine, initial_glide_s=0.0)
    library = ClipLibrary(shipped_clips_dir(), tmp_path)
    player = ClipPlayer(controller, library.get, start_margin_frames=0)
    clips.attach(controller, player)
    handler = register_tables(OscHandler(controller, sync_worker=None))
    yield engine, controller, player, handler
    clips.detach(controller, player)


def send(handler: OscHandler, address: str, *args, types: str | None = None) -> FakePeer:
    peer = FakePeer()
    handler.handle_packet(encode_message(address, args, types), peer)
    return peer


def run(engine: Engine, player: ClipPlayer, frames: int) -> None:
    end = engine.frame_position + frames
    while engine.frame_position < end:
        player.tick()
        engine.render(BLOCK)


def test_play_on_a_channel_drives_it_and_get_and_status_report_it(rig):
    engine, controller, player, handler = rig
    assert send(handler, "/vibsynth/ch/2/play", "heartbeat", 0.5, 2.0, 0, types="sffi").errors() == []
    run(engine, player, 800)  # 0.1 s
    playing = player.playing(1)
    assert (playing.name, playing.gain, playing.rate, playing.loops) == ("heartbeat", 0.5, 2.0, 0)
    assert player.playing(0) is None and controller.driver(1) == "clip" and controller.driver(0) == "knobs"
    reply = send(handler, "/vibsynth/ch/2/get", "clip").messages()
    assert [m.address for m in reply] == ["/vibsynth/ch/2/clip"] and reply[0].types == "sfi"
    name, position, left = reply[0].args
    assert name == "heartbeat" and left == -1 and position == pytest.approx(200.0, abs=2 * BLOCK / FS * 2000)
    both = send(handler, "/vibsynth/get", "clip").messages()
    assert [(m.address, m.args[0]) for m in both] == [("/vibsynth/ch/1/clip", ""), ("/vibsynth/ch/2/clip", "heartbeat")]
    status = send(handler, "/vibsynth/status").messages()[0].args
    pairs = dict(zip(status[::2], status[1::2]))
    assert pairs["clips_playing"] == 1 and pairs["ch2.clip"] == "heartbeat" and pairs["ch1.clip"] == ""
    assert pairs["ch2.clip_loops_left"] == -1 and pairs["ch2.clip_ms"] > 0
    send(handler, "/vibsynth/ch/2/stop", 30.0)
    run(engine, player, 800)
    assert player.playing(1) is None and controller.driver(1) == "knobs"
    assert send(handler, "/vibsynth/get", "clip").messages()[0].args == ("", 0.0, 0)


def test_global_play_and_stop_and_a_pattern_are_one_play(rig):
    engine, controller, player, handler = rig
    send(handler, "/vibsynth/play", "rain", types="s")
    run(engine, player, 400)
    assert player.playing(0).name == player.playing(1).name == "rain" and len(player._playbacks) == 1
    send(handler, "/vibsynth/ch/*/play", "zipper")
    run(engine, player, 400)
    assert player.playing(0).name == "zipper" and len(player._playbacks) == 1
    send(handler, "/vibsynth/stop")
    run(engine, player, 800)
    assert player.playing(0) is None and player.playing(1) is None


def test_a_timetagged_bundle_starts_the_clip_at_that_frame(rig):
    engine, controller, player, handler = rig
    run(engine, player, 4 * BLOCK)
    handler.clock.sample()
    when = time.time() + 0.5
    bundle = encode_bundle(unix_to_ntp(when), [encode_message("/vibsynth/ch/1/play", ("impact",))])
    handler.handle_packet(bundle, FakePeer())
    frame, _ = handler.clock.frame_at(when)
    playback = player._queues[0][0]
    assert abs(playback.start - frame) <= 2 and playback.start > engine.frame_position + 0.4 * FS
    assert not player.playing(0).started


@pytest.mark.parametrize(
    ("args", "types", "fragment", "kind"),
    [
        (("impakt",), "s", "unknown clip 'impakt'; did you mean impact?", "osc.clip"),
        (("impact", math.nan), "sf", "gain must be a finite number", "osc.invalid_value"),
        (("impact", 1.0, -2.0), "sff", "rate -2 is outside the allowed range [0.05, 20]", "osc.invalid_value"),
        (
            ("impact", 1.0, 1.0, 2**31 - 1),
            "sffi",
            "loops 2.14748e+09 is outside the allowed range [0, 10000]",
            "osc.invalid_value",
        ),
        (("impact", 1.0, 1.0, 2.5), "sfff", "loops must be a whole number", "osc.invalid_value"),
        (("impact", "loud"), "ss", "gain must be a number (OSC type i, f, d or h), got type 's'", "osc.bad_arguments"),
        ((3,), "i", "clip must be a string", "osc.bad_arguments"),
        ((), "", "expects 1 or 2 or 3 or 4 argument(s)", "osc.bad_arguments"),
        (("impact", 1.0, 1.0, 1, 5), "sffii", "expects 1 or 2 or 3 or 4 argument(s)", "osc.bad_arguments"),
        (("x" * 300,), "s", "clip name longer than 128 characters", "osc.invalid_value"),
    ],
)
def test_bad_plays_get_one_error_reply_and_change_nothing(rig, args, types, fragment, kind):
    engine, controller, player, handler = rig
    peer = send(handler, "/vibsynth/ch/1/play", *args, types=types)
    errors = peer.errors()
    assert len(errors) == 1 and errors[0][0] == "/vibsynth/ch/1/play"
    assert fragment in errors[0][1], errors[0][1]
    assert controller.error_counts == {kind: 1}
    assert player.playing(0) is None and engine.stats.pending == 0 and controller.driver(0) == "knobs"


def test_bad_stops_and_queries(rig):
    engine, controller, player, handler = rig
    assert (
        "release (ms) -5 is outside the allowed range [0, 10000]"
        in send(handler, "/vibsynth/stop", -5.0).errors()[0][1]
    )
    assert "expects 0 or 1 argument(s)" in send(handler, "/vibsynth/stop", 1.0, 2.0).errors()[0][1]
    assert "unknown setting 'clips'" in send(handler, "/vibsynth/get", "clips").errors()[0][1]
    assert send(handler, "/vibsynth/ch/9/play", "impact").errors()[0][1].startswith("channel 9 out of range")
    assert send(handler, "/vibsynth/ch/1/stop").errors() == []  # nothing playing: nothing to do


def test_without_a_player_play_is_refused_politely(bank):
    controller = Controller(Engine(bank, channels=1, max_block=BLOCK))
    handler = register_tables(OscHandler(controller, sync_worker=None))
    assert send(handler, "/vibsynth/play", "impact").errors() == [
        ("/vibsynth/play", "clips are not available (no clip player is running)")
    ]
    assert send(handler, "/vibsynth/get", "clip").messages()[0].args == ("", 0.0, 0)
    pairs = send(handler, "/vibsynth/status").messages()[0].args
    assert "clips_playing" not in pairs


def test_a_play_flood_stays_bounded_and_the_last_play_wins(rig):
    engine, controller, player, handler = rig
    rng = np.random.default_rng(11)
    names = ["impact", "rain", "zipper", "heartbeat", "gravel-steps", "nope"]
    batch = []
    for _ in range(5000):
        channel = int(rng.integers(1, 3))
        name = names[int(rng.integers(0, len(names)))]
        batch.append((encode_message(f"/vibsynth/ch/{channel}/play", (name, float(rng.uniform(0, 2)))), FakePeer()))
        if len(batch) == 100:
            handler.handle_batch(batch)
            batch = []
            run(engine, player, BLOCK)
    handler.handle_packet(encode_message("/vibsynth/ch/1/play", ("rain",)), FakePeer())
    assert engine.stats.pending <= player.max_queued and engine.stats.schedule_full == 0
    assert set(controller.error_counts) == {"osc.clip"}  # only the unknown names
    run(engine, player, BLOCK)
    assert player.playing(0).name == "rain" and len(player._playbacks) <= 4
