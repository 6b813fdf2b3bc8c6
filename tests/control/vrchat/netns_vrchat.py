"""Run inside a network namespace made by test_finder_netns.py: a scripted VRChat advertises itself, serve finds it.

The fake VRChat does what VRChat does on the network (its OSCQuery docs): it advertises
``VRChat-Client-XXXXXX`` as ``_oscjson._tcp`` and ``_osc._udp`` over mDNS and answers ``HOST_INFO``
with its OSC input (``OSC_PORT``: 9123 here, as VRChat started on another port); it browses for
OSCQuery services, keeps those whose tree has ``/avatar`` and sends its avatar parameters to the OSC
port their HOST_INFO names. Prints one JSON object with what each side saw.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
import urllib.request
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import vibsynth
from tests.netns import start_serve
from vibsynth.control.osc.codec import encode_message
from vibsynth.control.oscquery.discovery import Advertiser, discover

VRCHAT = "VRChat-Client-1A2B3C"
HOST_INFO = {
    "NAME": VRCHAT,
    "EXTENSIONS": {"ACCESS": True, "CLIPMODE": False, "RANGE": True, "TYPE": True, "VALUE": True},
    "OSC_IP": "127.0.0.1",
    "OSC_PORT": 9123,  # not the default: read from HOST_INFO
    "OSC_TRANSPORT": "UDP",
}


class VrchatHttp(BaseHTTPRequestHandler):
    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        body = json.dumps(HOST_INFO if "HOST_INFO" in self.path else {"FULL_PATH": "/", "ACCESS": 0}).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


def main(folder: str) -> None:
    http = ThreadingHTTPServer(("127.0.0.1", 0), VrchatHttp)
    threading.Thread(target=http.serve_forever, daemon=True).start()
    advertiser = Advertiser(VRCHAT, 9123, http.server_address[1], ["127.0.0.1"])
    advertiser.start()
    vrchat = "vrchat: {enabled: true, listen_port: 9001, parameters: [{name: Hug, channel: 1}]}\n"
    serve, _ = start_serve(folder, "vibsynth vest", extra=vrchat)
    out: dict = {}
    try:
        # VRChat's side: browse, keep the services whose tree has /avatar, send to their OSC port
        deadline = time.monotonic() + 30.0
        targets: list = []
        while not targets and time.monotonic() < deadline:
            for found in discover(2.0):
                if found.name == VRCHAT:
                    continue
                with urllib.request.urlopen(found.oscquery_url + "avatar", timeout=2) as response:  # noqa: S310
                    if json.loads(response.read()).get("FULL_PATH") == "/avatar":
                        targets.append(found)
        out["targets"] = [(t.name, t.osc) for t in targets]
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.sendto(encode_message("/avatar/parameters/Hug", (0.5,), "f"), (targets[0].osc_host, targets[0].osc_port))
        osc = vibsynth.Client("127.0.0.1", 9570)
        status: dict = {}
        while time.monotonic() < deadline:  # serve's own browse for VRChat takes a few seconds
            status = osc.status()
            if "found over mDNS" in str(status.get("vrchat.osc")):
                break
            time.sleep(0.5)
        out["vrchat_osc"] = status.get("vrchat.osc")
        out["intensity"] = osc.get("intensity")
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            probe.bind(("127.0.0.1", 9001))  # VRChat was found: serve closed its 9001 fallback socket
            out["fallback_closed"] = True
        except OSError:
            out["fallback_closed"] = False
        probe.close()
    finally:
        serve.terminate()
        serve.wait(20)
        advertiser.stop()
        http.shutdown()
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
