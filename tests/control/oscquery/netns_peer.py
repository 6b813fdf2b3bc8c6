"""Run inside a network namespace made by test_discovery_netns.py: serve, then browse it as others would.

Prints one JSON object with what python-oscquery read over zeroconf + HTTP, what ``get`` answered
over OSC, what ``vibsynth discover`` and ``Client.discover`` found, and an mDNS name conflict.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

from pythonoscquery.osc_query_browser import OSCQueryBrowser
from pythonoscquery.osc_query_client import OSCQueryClient

import vibsynth
from tests.netns import start_serve
from vibsynth.control.oscquery.discovery import Advertiser

NAME = "vibsynth netns"


def main(folder: str) -> None:
    serve, banner = start_serve(folder, NAME, seconds=40)
    out: dict = {"banner": banner}
    try:
        browser = OSCQueryBrowser()
        service, deadline = None, time.monotonic() + 20.0
        while service is None and time.monotonic() < deadline:  # mDNS probing and announcing take a while
            time.sleep(0.5)
            service = browser.find_service_by_name(NAME)
        assert service is not None, "python-oscquery found no service in 20 s"
        client = OSCQueryClient(service)
        info = client.get_host_info()
        out["host_info"] = {"name": info.name, "osc_ip": info.osc_ip, "osc_port": info.osc_port}
        root = client.query_node("/")
        out["paths"] = sorted(node.full_path for node in root)
        osc = vibsynth.Client(info.osc_ip, info.osc_port)
        osc.send("/vibsynth/intensity", 0.625)
        osc.send("/vibsynth/balance", -1.5)
        osc.sync()
        out["get"] = {"intensity": osc.get("intensity"), "balance": osc.get("balance")}
        out["tree"] = {
            "intensity": client.query_node("/vibsynth/ch/1/intensity").value,
            "balance": client.query_node("/vibsynth/balance").value,
        }
        out["raw"] = client.last_json
        osc.close()
        found = vibsynth.Client.discover("netns", interfaces=["127.0.0.1"], seconds=3.0)
        out["client_discover"] = found.get("intensity")
        found.close()
        listing = subprocess.run(
            [sys.executable, "-m", "vibsynth", "discover", "--seconds", "3", "--json"],
            capture_output=True,
            text=True,
            check=True,
        )
        out["discover"] = json.loads(listing.stdout)
        first = Advertiser("rival", 9590, 9592, ["127.0.0.1"])
        first.start()
        first.wait()
        rival = Advertiser("rival", 9580, 9582, ["127.0.0.1"])
        rival.start()
        rival.wait()
        out["conflict"] = {"conflicts": rival.conflicts, "name": rival.name, "failed": rival.failed}
        out["first"] = {"conflicts": first.conflicts, "name": first.name}
        rival.stop()
        first.stop()
        against_serve = Advertiser(NAME, 9560, 9562, ["127.0.0.1"])  # the name serve advertises
        against_serve.start()
        against_serve.wait()
        out["serve_conflict"] = {"conflicts": against_serve.conflicts, "name": against_serve.name}
        against_serve.stop()
        out["after_conflict"] = OSCQueryClient(service).get_host_info().osc_port
        browser.zc.close()
    finally:
        serve.terminate()
        serve.wait(10)
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
