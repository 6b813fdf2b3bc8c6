"""Run inside a network namespace made by test_csharp_discover.py: serve, then the C# client finds it.

Prints one JSON object: the C# program's ``key=value`` lines (what it discovered over mDNS and read
over OSCQuery and OSC).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import vibsynth
from tests.netns import start_serve

NAME = "vibsynth csharp"


def main(folder: str, exe: str) -> None:
    serve, _ = start_serve(folder, NAME)
    try:
        osc = vibsynth.Client("127.0.0.1", 9570)
        osc.send("/vibsynth/intensity", 0.375)
        osc.sync()
        found: dict[str, str] = {}
        attempts: list[str] = []
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:  # mDNS probing and announcing take a second or two
            done = subprocess.run(["mono", "--debug", exe, NAME], capture_output=True, text=True, timeout=60)
            found = dict(line.partition("=")[::2] for line in done.stdout.splitlines() if "=" in line)
            # the first runs may browse while serve still probes its name (about 1 s): until both
            # the listing (resolved: SRV and HOST_INFO answered in time) and the connection have seen it
            if "intensity" in found and found.get("service") == NAME and f"{NAME}.osc" in found:
                break
            attempts.append(f"exit {done.returncode}: {done.stdout[-300:]!r} {done.stderr[-300:]!r}")
            time.sleep(0.5)
        print(json.dumps({**found, "attempts": attempts, "serve_alive": serve.poll() is None}))
    finally:
        serve.terminate()
        serve.wait(20)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
