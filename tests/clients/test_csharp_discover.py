"""The C# client finds a server by mDNS + OSCQuery (VibsynthDiscovery), in a network namespace this test makes.

Multicast stays on the namespace's own loopback (never the machine's interfaces): ``vibsynth serve``
advertises there, the C# program (compiled with mcs, run with mono) browses, reads HOST_INFO over
HTTP and connects to the OSC port it names. A second test puts a scripted mDNS responder and
HOST_INFO server in serve's place (tests/clients/netns_resolve.py), whose answers come late or never.
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


def test_the_csharp_client_waits_for_late_answers_and_never_hands_out_an_unresolved_endpoint(tmp_path: Path):
    """A scripted responder answers PTR at once and SRV late or never; a scripted HOST_INFO drops requests.

    Issue 33: under load the client listed a found service at ``127.0.0.1:0`` (HOST_INFO had not
    answered and OscPort kept its default). Now it waits, within its timeout, for the SRV record
    (asking for it) and retries HOST_INFO; what stays unanswered is listed unresolved with the reason,
    its endpoint unreadable, and Connect says why.
    """
    require_mono()
    exe = compile_cs(tmp_path / "ResolveCheck.exe", CLIENT, HERE / "ResolveCheck.cs")
    out = run_in_netns(Path(__file__).with_name("netns_resolve.py"), exe)
    for name, seen in out.items():
        assert seen["exit"] == 0 and seen["found"] == "1", (name, seen)
        endpoints = [v for k, v in seen.items() if k.endswith(".osc") or k == "connected" or k.endswith(".port")]
        assert not any(str(v).endswith(":0") or v == "0" for v in endpoints), (name, seen)

    late = out["srv late"]  # SRV only from 0.8 s after the first query and the client's fourth SRV question
    assert late["srv_questions_before"] == 3 and late["srv_answered_at"] >= 0.8, late
    assert late["srv late.resolved"] == "true" and late["srv late.osc"] == "127.0.0.1:9581", late
    assert late["connected"] == "127.0.0.1:9581", late

    never = out["srv never"]
    reason = "no SRV record (its OSCQuery port) answered within 3 s"
    assert never["srv never.resolved"] == "false" and never["srv never.unresolved"] == reason, never
    assert never["srv never.text"] == f"srv never: unresolved ({reason})", never
    assert never["srv never.port_error"] == f"OSCQuery service 'srv never' is unresolved: {reason}", never
    assert never["connect_error"] == f"OSCQuery service 'srv never' found over mDNS but unresolved: {reason}", never
    assert "srv never.osc" not in never and never["host_info_requests"] == 0, never

    slow = out["host info late"]  # its first three HOST_INFO requests closed unanswered
    assert slow["host info late.osc"] == "127.0.0.1:9583" and slow["connected"] == "127.0.0.1:9583", slow
    assert slow["host_info_requests"] >= 4, slow

    gone = out["host info never"]
    url = f"http://127.0.0.1:{gone['http_port']}/?HOST_INFO"
    assert gone["host info never.resolved"] == "false", gone
    assert gone["host info never.unresolved"].startswith(f"its HOST_INFO ({url}) did not answer within 3 s ("), gone
    assert gone["host info never.port_error"].startswith("OSCQuery service 'host info never' is unresolved: "), gone
    assert gone["connect_error"].startswith("OSCQuery service 'host info never' found over mDNS but unresolved: "), gone
    assert gone["host_info_requests"] >= 2, gone  # retried, not given up after one

    portless = out["host info without port"]
    url = f"http://127.0.0.1:{portless['http_port']}/?HOST_INFO"
    assert portless["host info without port.unresolved"] == f"its HOST_INFO ({url}) names no OSC_PORT in 1..65535"
    assert portless["connect_error"].endswith(f"unresolved: its HOST_INFO ({url}) names no OSC_PORT in 1..65535")
