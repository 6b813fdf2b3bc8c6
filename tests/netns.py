"""Private network namespaces for the discovery tests (mDNS multicast on the namespace's own loopback only).

The test side (:data:`NETNS`, :func:`run_in_netns`) runs a driver script inside a new namespace
(``unshare -n``, loopback up with a multicast route); the driver side (:func:`start_serve`) starts
``vibsynth serve`` there, advertised on 127.0.0.1, and waits for its OSCQuery banner. A driver
prints one JSON object as its last line: what it saw.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from http.server import BaseHTTPRequestHandler
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The namespace's loopback: up, multicast, and the multicast route (mDNS' 224.0.0.251).
SETUP = "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo"

#: Skip marker of the tests that make a namespace.
NETNS = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("unshare") is None or shutil.which("ip") is None,
    reason="needs root, unshare and ip (iproute2) to make a network namespace",
)


def run_in_netns(driver: Path, *args: object, timeout: float = 150.0) -> dict[str, Any]:
    """Run ``python driver ARGS`` in a new network namespace; the JSON object it printed last.

    The driver gets this checkout on ``PYTHONPATH`` and no ``VIBSYNTH_CONFIG`` of the caller.

    Raises
    ------
    AssertionError
        The driver failed (with the end of its standard error).
    """
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("VIBSYNTH_CONFIG", None)
    result = subprocess.run(
        ["unshare", "-n", "bash", "-c", f'{SETUP} && exec "$0" "$@"', sys.executable, str(driver), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out: dict[str, Any] = json.loads(result.stdout.strip().splitlines()[-1])
    return out


def start_serve(folder: str | Path, name: str, *, seconds: int = 60, extra: str = "") -> tuple[subprocess.Popen, str]:
    """In a namespace: ``vibsynth serve`` (OSC 9570, OSCQuery 9572, advertised as ``name`` on 127.0.0.1).

    ``extra``: more YAML lines for its config. Returns the process (stdout piped) and its
    ``oscquery: URL`` banner line, once printed (serve answers OSC and OSCQuery from then on).
    """
    cfg = Path(folder) / "config.yaml"
    cfg.write_text(
        "osc: {port: 9570}\nstudio: {enabled: false}\nmidi: {enabled: false}\n"
        f"discovery: {{name: '{name}', interfaces: ['127.0.0.1'], oscquery_port: 9572}}\n{extra}"
    )
    cmd = [sys.executable, "-m", "vibsynth", "serve", "--config", str(cfg), "--output", "null"]
    serve = subprocess.Popen([*cmd, "--seconds", str(seconds)], stdout=subprocess.PIPE, text=True)
    assert serve.stdout is not None
    for line in serve.stdout:
        if line.startswith("oscquery: "):
            return serve, line.strip()
    serve.wait(20)
    raise AssertionError(f"serve exited ({serve.returncode}) before its OSCQuery banner")


def send_json(handler: BaseHTTPRequestHandler, tree: object) -> None:
    """Answer a scripted HTTP server's request (an OSCQuery tree, a HOST_INFO) with ``tree`` as JSON."""
    body = json.dumps(tree).encode()
    handler.send_response(200)
    handler.send_header("Content-Type", "application/json")
    handler.send_header("Content-Length", str(len(body)))
    handler.end_headers()
    handler.wfile.write(body)
