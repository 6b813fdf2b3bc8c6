"""``vibsynth clip play`` / ``clip stop`` against a real OSC server with a clip player (in-process engine)."""

from __future__ import annotations

import pytest

from vibsynth.cli import main
from vibsynth.control import clips
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.controller import Controller
from vibsynth.control.osc.server import OscServer
from vibsynth.engine.bank import BankSpec, build_bank
from vibsynth.engine.engine import Engine
from vibsynth.formats.basis_file import default_basis
from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir


@pytest.fixture
def served(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBSYNTH_CONFIG", str(tmp_path / "none.yaml"))
    engine = Engine(build_bank(default_basis(), BankSpec(fs=8000.0, loop_seconds=1.0, levels=5)), channels=2)
    controller = Controller(engine)
    player = ClipPlayer(controller, ClipLibrary(shipped_clips_dir(), tmp_path).get)
    clips.attach(controller, player)
    server = OscServer(controller, port=0)
    server.start()
    try:
        yield engine, player, str(server.port)
    finally:
        server.stop()
        clips.detach(controller, player)


def test_play_and_stop_reach_the_player(served, capsys):
    engine, player, port = served
    assert main(["clip", "play", "heartbeat", "--channel", "2", "--gain", "0.5", "--loops", "0", "--port", port]) == 0
    assert capsys.readouterr() == ("", "")
    playing = player.playing(1)
    assert (playing.name, playing.gain, playing.loops) == ("heartbeat", 0.5, 0) and player.playing(0) is None
    assert main(["clip", "play", "impact", "--at", "2", "--port", port]) == 0
    waiting = player.playing(0)
    assert waiting.name == "impact" and not waiting.started
    assert main(["clip", "stop", "--channel", "2", "--release", "40", "--port", port]) == 0
    assert player.stats.stops == 1


def test_an_unknown_clip_prints_the_server_error_and_exits_1(served, capsys):
    engine, player, port = served
    assert main(["clip", "play", "hartbeat", "--port", port]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.startswith(
        "vibsynth: error: /vibsynth/play: unknown clip 'hartbeat'; did you mean heartbeat?"
    )
    assert err.count("\n") == 1 and player.stats.plays == 0
