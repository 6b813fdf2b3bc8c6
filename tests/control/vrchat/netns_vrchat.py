"""Run inside a network namespace made by test_finder_netns.py: a scripted VRChat advertises itself, serve finds it.

The fake VRChat does what VRChat does on the network (its OSCQuery docs): it advertises
``VRChat-Client-XXXXXX`` as ``_oscjson._tcp`` and ``_osc._udp`` over mDNS and answers ``HOST_INFO``
with its OSC input (``OSC_PORT``: 9123 here, as VRChat started on another port); it browses for
OSCQuery services, keeps those whose tree has ``/avatar`` and sends its avatar parameters to the OSC
port their HOST_INFO names. Its own tree holds the avatar's current parameter values, as
VRChat's does: a hand already resting (``Held`` 0.6) and a bool already true (``Poke``, a clip),
which serve reads once it finds VRChat. Prints one JSON object with what each side saw.
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
from tests.netns import send_json, start_serve
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


AVATAR_ID = "avtr_11111111-2222-4333-8444-555555555555"
#: VRChat's /avatar node: the avatar's id and each parameter's current value (names with "/" nest).
AVATAR = {
    "FULL_PATH": "/avatar",
    "ACCESS": 0,
    "CONTENTS": {
        "change": {"FULL_PATH": "/avatar/change", "TYPE": "s", "ACCESS": 3, "VALUE": [AVATAR_ID]},
        "parameters": {
            "FULL_PATH": "/avatar/parameters",
            "ACCESS": 0,
            "CONTENTS": {
                "Held": {"FULL_PATH": "/avatar/parameters/Held", "TYPE": "f", "ACCESS": 3, "VALUE": [0.6]},
                "Poke": {"FULL_PATH": "/avatar/parameters/Poke", "TYPE": "T", "ACCESS": 3, "VALUE": [True]},
                "Grounded": {"FULL_PATH": "/avatar/parameters/Grounded", "TYPE": "T", "ACCESS": 3, "VALUE": [True]},
                "Go": {
                    "FULL_PATH": "/avatar/parameters/Go",
                    "ACCESS": 0,
                    "CONTENTS": {
                        "Hand": {"FULL_PATH": "/avatar/parameters/Go/Hand", "TYPE": "i", "ACCESS": 3, "VALUE": [1]}
                    },
                },
            },
        },
    },
}


class VrchatHttp(BaseHTTPRequestHandler):
    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        if "HOST_INFO" in self.path:
            tree: dict = HOST_INFO
        elif self.path.startswith("/avatar"):
            tree = AVATAR
        else:
            tree = {"FULL_PATH": "/", "ACCESS": 0}
        send_json(self, tree)

    def log_message(self, *args: object) -> None:
        pass


def main(folder: str) -> None:
    http = ThreadingHTTPServer(("127.0.0.1", 0), VrchatHttp)
    threading.Thread(target=http.serve_forever, daemon=True).start()
    advertiser = Advertiser(VRCHAT, 9123, http.server_address[1], ["127.0.0.1"])
    advertiser.start()
    vrchat = (
        "audio: {channels: 4}\n"
        "vrchat: {enabled: true, listen_port: 9001, parameters: [{name: Hug, channel: 1}, {name: Held, channel: 2},"
        " {name: Go/Hand, channel: 3}, {name: Poke, clip: impact, channel: 4}]}\n"
    )
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
        while time.monotonic() < deadline and status.get("vrchat.primed", 0) < 3:
            time.sleep(0.2)
            status = osc.status()
        out["primed"] = status.get("vrchat.primed")
        out["avatar"] = status.get("vrchat.avatar")
        out["held"] = osc.get("intensity", channel=2)  # read from VRChat's tree: no message was sent
        out["hand"] = osc.get("intensity", channel=3)
        out["poke_clip"] = status.get("ch4.clip")  # already true: a state, not a rising edge
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
