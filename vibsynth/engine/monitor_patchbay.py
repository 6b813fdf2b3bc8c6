"""The JACK patch bay of ``--follow monitor``, run in a child process of serve.

It connects serve's PortAudio input ports to every port that feeds the system's playback ports
(``system:playback_N``), excluding serve's own outputs, and looks again every ``--poll`` seconds.

Why a child process: libjack keeps per-process state. A JACK client left in serve's process when
its server dies cannot be closed (``jack_client_close`` on a dead server aborts, as PortAudio's
``Pa_Terminate`` does: see :mod:`vibsynth.engine.pa_runtime`) and, left open, makes the process
crash (SIGSEGV, measured with jack2 1.9.21) when PortAudio opens its client on the restarted server.
The child exits at once (``os._exit``) when its server shuts down or serve is gone;
:class:`~vibsynth.engine.monitor.MonitorInput` starts another.

Protocol: one JSON object per line on stdout: ``{"ready": true}`` once it has noted the PortAudio
input ports there are (serve's appear after: they are its own), then
``{"own": [...], "sources": [...], "connections": N}`` whenever that changes, or
``{"error": "..."}`` before it exits with code 3.

Usage: ``python -m vibsynth.engine.monitor_patchbay --channels 2 --parent PID [--own P1,P2]``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import threading
from types import ModuleType
from typing import Any

from vibsynth.errors import DeviceError

__all__ = ["JackPatcher", "import_jack", "main"]

#: Input ports a PortAudio client holds on JACK (``PortAudio``, or ``PortAudio-01`` when taken).
_PA_IN = re.compile(r"^(PortAudio[^:]*):in_(\d+)$")


def import_jack() -> ModuleType:
    """The JACK-Client package, or one clear :class:`DeviceError` saying how to get it."""
    try:
        import jack
    except (ImportError, OSError) as exc:
        raise DeviceError(
            f"the JACK monitor input needs the JACK-Client package ({exc}): pip install 'vibsynth[monitor]'"
        ) from None
    module: ModuleType = jack
    return module


def _port_number(name: str) -> int:
    match = _PA_IN.match(name)
    return int(match.group(2)) if match else -1


class JackPatcher:
    """Connects our PortAudio input ports to what feeds ``system:playback_N`` (polled).

    Parameters
    ----------
    client : jack.Client
        A client of the JACK server (the patch bay's own).
    channels : int
        Our input ports; playback port ``k`` (0-based) feeds ours ``k mod channels``.
    own : list of str, optional
        Our input ports as they were named before (a restarted server): taken again when present.
    """

    def __init__(self, client: Any, channels: int, own: list[str] | None = None) -> None:
        self.client = client
        self.channels = int(channels)
        self._previous = list(own or [])
        self._seen: set[str] = set()
        #: our PortAudio client's input ports, in order (found when they appear)
        self.own: list[str] = []
        #: the ports feeding the system's playback, as connected last
        self.sources: list[str] = []
        self.connections = 0

    def _in_ports(self) -> set[str]:
        return {p.name for p in self.client.get_ports(is_audio=True, is_input=True) if _PA_IN.match(p.name)}

    def snapshot(self) -> None:
        """Note the PortAudio input ports there are now: ports that appear later are ours."""
        self._seen = self._in_ports()

    def poll(self) -> None:
        """Find our ports (once they appear), then connect each to every feeder of its playback ports."""
        client = self.client
        ins = self._in_ports()
        if not self.own or not set(self.own) <= ins:
            if self._previous and set(self._previous) <= ins:
                self.own = list(self._previous)
            else:
                new = sorted(ins - self._seen, key=_port_number)
                owners = {n.split(":", 1)[0] for n in new}
                self.own = new if len(owners) == 1 and len(new) >= self.channels else []
        self._seen = ins
        if not self.own:
            return
        self._previous = list(self.own)
        ours = self.own[0].split(":", 1)[0] + ":"
        mine = str(client.name) + ":"
        wanted: dict[str, set[str]] = {name: set() for name in self.own[: self.channels]}
        playback = client.get_ports(is_audio=True, is_input=True, is_physical=True)
        sources: list[str] = []
        for k, port in enumerate(playback):
            for feeder in client.get_all_connections(port):
                if feeder.name.startswith(ours) or feeder.name.startswith(mine):
                    continue  # serve's own outputs do not feed its input
                wanted[self.own[k % self.channels]].add(feeder.name)
                sources.append(feeder.name)
        for name, feeders in wanted.items():
            have = {p.name for p in client.get_all_connections(client.get_port_by_name(name))}
            for feeder in sorted(feeders - have):
                if _quietly(client.connect, feeder, name):
                    self.connections += 1
            for stale in sorted(have - feeders):  # PortAudio's own link to system:capture, gone sources
                _quietly(client.disconnect, stale, name)
        self.sources = sorted(set(sources))

    def state(self) -> dict[str, Any]:
        return {"own": list(self.own), "sources": list(self.sources), "connections": self.connections}


def _quietly(change: Any, source: str, destination: str) -> bool:
    """One connect or disconnect; False when JACK refused it (a port that went between the listing and
    now, a link PortAudio made or removed meanwhile): the next poll looks again, the rest goes on."""
    try:
        change(source, destination)
    except Exception:  # noqa: BLE001 - jack.JackError (the module is imported in the child only)
        return False
    return True


def _say(message: dict[str, Any]) -> None:
    print(json.dumps(message), flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run the patch bay until the server or the parent is gone (see the module notes)."""
    parser = argparse.ArgumentParser(prog="python -m vibsynth.engine.monitor_patchbay")
    parser.add_argument("--channels", type=int, default=2)
    parser.add_argument("--parent", type=int, required=True)
    parser.add_argument("--own", default="")
    parser.add_argument("--poll", type=float, default=0.25)
    args = parser.parse_args(argv)
    try:
        jack = import_jack()
        client = jack.Client(f"vibsynth-monitor-{args.parent}", no_start_server=True)
    except Exception as exc:  # noqa: BLE001 - no package, no server: said, and the parent tries again
        _say({"error": f"JACK: {exc}"})
        return 3
    gone = threading.Event()
    client.set_shutdown_callback(lambda status, reason: gone.set())
    client.activate()
    patcher = JackPatcher(client, args.channels, [p for p in args.own.split(",") if p])
    patcher.snapshot()
    _say({"ready": True})
    said: dict[str, Any] = {}
    while not gone.wait(args.poll):
        if os.getppid() != args.parent:
            break
        try:
            patcher.poll()
        except Exception as exc:  # noqa: BLE001 - the server is going: the shutdown callback follows
            _say({"error": f"JACK: {exc}"})
            break
        state = patcher.state()
        if state != said:
            _say(state)
            said = state
    os._exit(0)  # never close a client of a dead server (libjack aborts); the process takes it along


if __name__ == "__main__":  # pragma: no cover - run by MonitorInput
    raise SystemExit(main())
