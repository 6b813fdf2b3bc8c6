"""The C# client finds a server by mDNS + OSCQuery (VibsynthDiscovery), in a network namespace this test makes.

Multicast stays on the namespace's own loopback (never the machine's interfaces): ``vibsynth serve``
advertises there, the C# program (compiled with mcs, run with mono) browses, reads HOST_INFO over
HTTP and connects to the OSC port it names.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.clients.mono import CLIENT, HERE, compile_cs, require_mono

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("unshare") is None or shutil.which("ip") is None,
    reason="needs root, unshare and ip (iproute2) to make a network namespace",
)

SETUP = "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo"


def test_the_csharp_client_discovers_serve_over_mdns_and_oscquery(tmp_path: Path):
    require_mono()
    exe = compile_cs(tmp_path / "DiscoverCheck.exe", CLIENT, HERE / "DiscoverCheck.cs")
    driver = Path(__file__).with_name("netns_discover.py")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    env.pop("VIBSYNTH_CONFIG", None)
    result = subprocess.run(
        [
            "unshare",
            "-n",
            "bash",
            "-c",
            f'{SETUP} && exec "$0" "$@"',
            sys.executable,
            str(driver),
            str(tmp_path),
            str(exe),
        ],
        capture_output=True,
        text=True,
        timeout=150,
        env=env,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["service"] == "vibsynth csharp" and int(out["found"]) >= 1
    assert out["vibsynth csharp.url"] == "http://127.0.0.1:9572/"
    assert out["vibsynth csharp.osc"] == "127.0.0.1:9570" and out["vibsynth csharp.transport"] == "UDP"
    assert float(out["intensity"]) == pytest.approx(0.375)  # Connect() reached the server HOST_INFO named
    assert out["missing"] == "no OSCQuery service named like 'no such service' found over mDNS"
