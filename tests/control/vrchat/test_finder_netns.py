"""VRChat and vibsynth find each other over mDNS + OSCQuery, in a network namespace this test makes.

A scripted VRChat (tests/control/vrchat/netns_vrchat.py) advertises ``VRChat-Client-1A2B3C`` with its
HOST_INFO; it finds ``vibsynth serve`` by its tree's ``/avatar`` and sends an avatar parameter to the
OSC port serve's HOST_INFO names; serve finds VRChat, reads its OSC input from HOST_INFO and closes its
fallback socket on VRChat's output port. Multicast stays on the namespace's own loopback.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from vibsynth.control.oscquery.discovery import Found
from vibsynth.control.vrchat.finder import pick

SETUP = "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo"
NETNS = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("unshare") is None or shutil.which("ip") is None,
    reason="needs root, unshare and ip (iproute2) to make a network namespace",
)


def test_pick_takes_vrchats_host_info_or_the_fallback():
    other = Found("vibsynth on pc", "http://10.0.0.2:9572/", "10.0.0.2", 9570)
    vrchat = Found("VRChat-Client-ABCDEF", "http://10.0.0.3:37001/", "10.0.0.3", 9000)
    mute = Found("VRChat-Client-000000", "http://10.0.0.4:37001/", None, None)  # no HOST_INFO answer
    assert pick([other, mute, vrchat], "127.0.0.1", 9000).describe() == "udp://10.0.0.3:9000 (found over mDNS)"
    fallback = pick([other, mute], "127.0.0.1", 9000)
    assert (fallback.host, fallback.port, fallback.found) == ("127.0.0.1", 9000, False)


@NETNS
def test_vrchat_and_serve_find_each_other_in_a_private_namespace(tmp_path: Path):
    driver = Path(__file__).with_name("netns_vrchat.py")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])}
    env.pop("VIBSYNTH_CONFIG", None)
    result = subprocess.run(
        ["unshare", "-n", "bash", "-c", f'{SETUP} && exec "$0" "$@"', sys.executable, str(driver), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=150,
        env=env,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["targets"] == [["vibsynth vest", "udp://127.0.0.1:9570"]]  # VRChat keeps services with /avatar
    assert out["intensity"] == pytest.approx(0.5)  # the parameter it sent drove channel 1
    assert out["vrchat_osc"] == "udp://127.0.0.1:9123 (found over mDNS)"  # from its HOST_INFO
    assert out["fallback_closed"] is True
