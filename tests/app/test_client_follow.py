"""vibsynth.Client's live Follow methods against a real OSC server and a follower fed by a fake input."""

from __future__ import annotations

import pytest

from tests.control.follow.fakes import Rig, tone
from vibsynth.app.client import Client
from vibsynth.control import follow
from vibsynth.control.osc.server import OscServer
from vibsynth.errors import ParameterError, ServerError

FS = 16000.0


@pytest.fixture(scope="module")
def bank(basis):
    from vibsynth.engine.bank import BankSpec, build_bank

    return build_bank(basis, BankSpec(fs=FS, loop_seconds=1.0, levels=9, seed=2))


@pytest.fixture
def served(bank, basis):
    rig = Rig(bank, basis, channels=2, follow={"mode": "audio"})
    follow.attach(rig.controller, rig.follower)
    server = OscServer(rig.controller, port=0)
    server.start()
    client = Client(port=server.port, timeout=2.0)
    yield rig, client
    client.close()
    server.stop()
    follow.detach(rig.controller, rig.follower)


def test_gain_gate_focus_and_per_channel_follow_round_trip(served):
    rig, client = served
    client.set_follow_gain(-6.5)
    client.set_follow_gate(-48.0)
    client.set_follow_focus("bass")
    client.set_follow_range(30.0)
    assert client.follow_setting("gain") == -6.5
    assert client.follow_setting("range") == 30.0
    assert rig.follower.range_db == 30.0
    assert client.follow_setting("gate") == -48.0
    assert client.follow_setting("focus") == "bass"
    rig.feed(tone(FS, 0.2, 0.05))
    client.set_follow(False, channel=2)
    assert client.get("follow", 2) is False and client.get("follow", 1) is True
    assert client.get("driver", 2) == "knobs"
    client.set_follow(True)
    assert client.get("follow", 2) is True


def test_bad_values_are_refused_by_the_server_or_before_sending(served):
    rig, client = served
    client.set_follow_gain(99.0)
    with pytest.raises(ServerError, match=r"outside the allowed range \[-60, 60\]"):
        client.sync()
    with pytest.raises(ParameterError, match="unknown follow setting"):
        client.follow_setting("volume")
    with pytest.raises(ParameterError, match="finite"):
        client.set_follow_gate(float("nan"))
    client.set_follow_range(2.0)
    with pytest.raises(ServerError, match=r"outside the allowed range \[6, 120\]"):
        client.sync()
    assert rig.follower.gain_db == 0.0
