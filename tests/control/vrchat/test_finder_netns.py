"""VRChat and vibsynth find each other over mDNS + OSCQuery, in a network namespace this test makes.

A scripted VRChat (tests/control/vrchat/netns_vrchat.py) advertises ``VRChat-Client-1A2B3C`` with its
HOST_INFO; it finds ``vibsynth serve`` by its tree's ``/avatar`` and sends an avatar parameter to the
OSC port serve's HOST_INFO names; serve finds VRChat, reads its OSC input from HOST_INFO and closes its
fallback socket on VRChat's output port. Multicast stays on the namespace's own loopback.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.netns import NETNS, run_in_netns
from vibsynth.control.oscquery.discovery import Found
from vibsynth.control.vrchat.finder import pick


def test_pick_takes_vrchats_host_info_or_the_fallback():
    other = Found("vibsynth on pc", "http://10.0.0.2:9572/", "10.0.0.2", 9570)
    vrchat = Found("VRChat-Client-ABCDEF", "http://10.0.0.3:37001/", "10.0.0.3", 9000)
    mute = Found("VRChat-Client-000000", "http://10.0.0.4:37001/", None, None)  # no HOST_INFO answer
    assert pick([other, mute, vrchat], "127.0.0.1", 9000).describe() == "udp://10.0.0.3:9000 (found over mDNS)"
    fallback = pick([other, mute], "127.0.0.1", 9000)
    assert (fallback.host, fallback.port, fallback.found) == ("127.0.0.1", 9000, False)


@NETNS
def test_vrchat_and_serve_find_each_other_in_a_private_namespace(tmp_path: Path):
    out = run_in_netns(Path(__file__).with_name("netns_vrchat.py"), tmp_path)
    assert out["targets"] == [["vibsynth vest", "udp://127.0.0.1:9570"]]  # VRChat keeps services with /avatar
    assert out["intensity"] == pytest.approx(0.5)  # the parameter it sent drove channel 1
    assert out["vrchat_osc"] == "udp://127.0.0.1:9123 (found over mDNS)"  # from its HOST_INFO
    assert out["fallback_closed"] is True
    # VRChat's current values, read from its tree once found: a resting hand is felt without a message
    assert out["primed"] == 3 and out["avatar"] == "avtr_11111111-2222-4333-8444-555555555555"
    assert out["held"] == pytest.approx(0.6) and out["hand"] == pytest.approx(1.0)
    assert out["poke_clip"] == ""  # a bool already true plays nothing
