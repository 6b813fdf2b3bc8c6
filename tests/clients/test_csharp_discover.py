"""The C# client finds a server by mDNS + OSCQuery (VibsynthDiscovery), in a network namespace this test makes.

Multicast stays on the namespace's own loopback (never the machine's interfaces): ``vibsynth serve``
advertises there, the C# program (compiled with mcs, run with mono) browses, reads HOST_INFO over
HTTP and connects to the OSC port it names.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.clients.mono import CLIENT, HERE, compile_cs, require_mono
from tests.netns import NETNS, run_in_netns

pytestmark = NETNS


def test_the_csharp_client_discovers_serve_over_mdns_and_oscquery(tmp_path: Path):
    require_mono()
    exe = compile_cs(tmp_path / "DiscoverCheck.exe", CLIENT, HERE / "DiscoverCheck.cs")
    out = run_in_netns(Path(__file__).with_name("netns_discover.py"), tmp_path, exe)
    assert out.get("service") == "vibsynth csharp" and int(out["found"]) >= 1, out
    assert out["vibsynth csharp.url"] == "http://127.0.0.1:9572/"
    assert out["vibsynth csharp.osc"] == "127.0.0.1:9570" and out["vibsynth csharp.transport"] == "UDP"
    assert float(out["intensity"]) == pytest.approx(0.375)  # Connect() reached the server HOST_INFO named
    assert out["missing"] == "no OSCQuery service named like 'no such service' found over mDNS"
