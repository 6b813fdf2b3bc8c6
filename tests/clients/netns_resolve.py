"""Run inside a network namespace made by test_csharp_discover.py: the C# client against late or missing answers.

A scripted mDNS responder (a ``_oscjson._tcp`` service: PTR answered at once, its SRV record only from
a given delay after the first query, or never) and a scripted HOST_INFO server (dropping its first
requests unanswered, or all of them, or naming no OSC port) stand in for a server, one scenario after
the other; the C# program (``ResolveCheck.cs``) discovers and connects. Prints one JSON object:
scenario -> the program's ``key=value`` lines and what the responders saw.
"""

from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from zeroconf import DNSAddress, DNSIncoming, DNSOutgoing, DNSPointer, DNSService
from zeroconf.const import _CLASS_IN, _CLASS_UNIQUE, _FLAGS_AA, _FLAGS_QR_RESPONSE, _TYPE_A, _TYPE_PTR, _TYPE_SRV

from tests.netns import send_json

TYPE = "_oscjson._tcp.local."
GROUP = "224.0.0.251"

#: name -> (SRV delay after the first query in s, None = never; HOST_INFO requests dropped first;
#: HOST_INFO's OSC_PORT, None = left out; the client's timeout in s). What must resolve gets a timeout
#: far above its delays (a loaded machine's mono makes its first HTTP request slowly); what never
#: answers needs only the time for the PTR answer.
SCENARIOS: dict[str, tuple[float | None, int, int | None, float]] = {
    "srv late": (0.8, 0, 9581, 6.0),
    "srv never": (None, 0, 9582, 3.0),
    "host info late": (0.0, 3, 9583, 6.0),
    "host info never": (0.0, 10**6, 9584, 3.0),
    "host info without port": (0.0, 0, None, 3.0),
}


class Responder:
    """Answers mDNS queries for one ``_oscjson._tcp`` instance by unicast (the client's one-shot queries).

    A PTR question gets the PTR record alone (no SRV or A in the additional records); an SRV question
    for the instance gets SRV + A once ``srv_after`` seconds have passed since the first query and
    three SRV questions went unanswered (so the client is seen to ask again however slowly it runs).
    """

    def __init__(self, name: str, http_port: int, srv_after: float | None) -> None:
        self.instance = f"{name}.{TYPE}"
        self.host = "scripted-host.local."
        self.http_port, self.srv_after = http_port, srv_after
        self.first: float | None = None
        self.srv_questions_before = self.srv_questions_after = 0
        self.srv_answered_at: float | None = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("0.0.0.0", 5353))
        mreq = struct.pack("4s4s", socket.inet_aton(GROUP), socket.inet_aton("127.0.0.1"))
        self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
        self.sock.settimeout(0.1)
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        while not self.stopping.is_set():
            try:
                data, sender = self.sock.recvfrom(9000)
            except TimeoutError:
                continue
            now = time.monotonic()
            message = DNSIncoming(data)
            if not message.is_query():
                continue
            if self.first is None:
                self.first = now
            out = DNSOutgoing(_FLAGS_QR_RESPONSE | _FLAGS_AA, multicast=False)
            answered = False
            for question in message.questions:
                if question.type == _TYPE_PTR and question.name.lower() == TYPE:
                    out.add_answer_at_time(DNSPointer(TYPE, _TYPE_PTR, _CLASS_IN, 120, self.instance), 0)
                    answered = True
                elif question.type == _TYPE_SRV and question.name.lower() == self.instance.lower():
                    if self.srv_after is None or now - self.first < self.srv_after or self.srv_questions_before < 3:
                        self.srv_questions_before += 1
                        continue
                    self.srv_questions_after += 1
                    if self.srv_answered_at is None:
                        self.srv_answered_at = now - self.first
                    srv = DNSService(
                        self.instance, _TYPE_SRV, _CLASS_IN | _CLASS_UNIQUE, 120, 0, 0, self.http_port, self.host
                    )
                    out.add_answer_at_time(srv, 0)
                    address = DNSAddress(
                        self.host, _TYPE_A, _CLASS_IN | _CLASS_UNIQUE, 120, socket.inet_aton("127.0.0.1")
                    )
                    out.add_answer_at_time(address, 0)
                    answered = True
            if answered:
                for packet in out.packets():
                    self.sock.sendto(packet, sender)

    def close(self) -> None:
        self.stopping.set()
        self.thread.join(5)
        self.sock.close()


def host_info_server(http_port: int, drop: int, osc_port: int | None) -> ThreadingHTTPServer:
    """``GET /?HOST_INFO``: the first ``drop`` requests closed unanswered, then HOST_INFO (``OSC_PORT`` if given)."""
    info: dict[str, Any] = {"NAME": "scripted", "OSC_IP": "127.0.0.1", "OSC_TRANSPORT": "UDP"}
    if osc_port is not None:
        info["OSC_PORT"] = osc_port
    seen = {"requests": 0}

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            seen["requests"] += 1
            if seen["requests"] <= drop:
                self.close_connection = True
                return  # the connection closes with no answer
            send_json(self, info)

        def log_message(self, *args: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", http_port), Handler)
    server.seen = seen  # type: ignore[attr-defined]
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def main(exe: str) -> None:
    results: dict[str, dict[str, Any]] = {}
    for k, (name, (srv_after, drop, osc_port, timeout)) in enumerate(SCENARIOS.items()):
        http_port = 9601 + k
        server = host_info_server(http_port, drop, osc_port)
        responder = Responder(name, http_port, srv_after)
        try:
            done = subprocess.run(
                ["mono", "--debug", exe, str(timeout), name], capture_output=True, text=True, timeout=60
            )
        finally:
            responder.close()
            server.shutdown()
            server.server_close()
        lines = dict(line.partition("=")[::2] for line in done.stdout.splitlines() if "=" in line)
        results[name] = {
            **lines,
            "exit": done.returncode,
            "stderr": done.stderr[-2000:],
            "http_port": http_port,
            "srv_questions_before": responder.srv_questions_before,
            "srv_questions_after": responder.srv_questions_after,
            "srv_answered_at": responder.srv_answered_at,
            "host_info_requests": server.seen["requests"],  # type: ignore[attr-defined]
        }
    print(json.dumps(results))


if __name__ == "__main__":
    main(sys.argv[1])
