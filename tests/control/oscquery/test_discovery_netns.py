"""Discovery end to end in a network namespace this test makes (multicast on its own loopback only).

python-oscquery (an OSCQuery client written elsewhere) finds ``vibsynth serve`` over zeroconf
and reads types, ranges and values that agree with ``get`` over OSC; ``vibsynth discover``
and ``Client.discover`` find it; a second service with the same name is renamed once and
counted, the first keeps answering.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.netns import NETNS, run_in_netns

pytestmark = NETNS


def test_python_oscquery_browses_the_service_in_a_private_namespace(tmp_path: Path):
    out = run_in_netns(Path(__file__).with_name("netns_peer.py"), tmp_path, timeout=120)
    assert out["banner"] == "oscquery: http://127.0.0.1:9572/"
    assert out["host_info"] == {"name": "vibsynth netns", "osc_ip": "127.0.0.1", "osc_port": 9570}
    assert "/vibsynth/ch/1/intensity" in out["paths"] and "/vibsynth/status" in out["paths"]
    assert out["get"]["intensity"] == pytest.approx(out["tree"]["intensity"][0]) == pytest.approx(0.625)
    assert out["get"]["balance"] == pytest.approx(out["tree"]["balance"][0]) == pytest.approx(-1.5)
    assert out["raw"]["TYPE"] == "f" and out["raw"]["RANGE"][0]["MIN"] < -1.5 < out["raw"]["RANGE"][0]["MAX"]
    assert {"name": "vibsynth netns", "osc": "udp://127.0.0.1:9570", "oscquery": "http://127.0.0.1:9572/"} in out[
        "discover"
    ]
    assert out["client_discover"] == pytest.approx(0.625)  # Client.discover() reached the same server
    assert out["first"] == {"conflicts": 0, "name": "rival"}
    assert out["conflict"]["conflicts"] == 1 and out["conflict"]["name"] == "rival-2"
    assert out["serve_conflict"] == {"conflicts": 1, "name": "vibsynth netns-2"}  # across processes too
    assert out["conflict"]["failed"] is None and out["after_conflict"] == 9570
