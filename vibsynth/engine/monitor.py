"""``--follow monitor``: follow what the system plays (a loopback / monitor input), where it has one.

:class:`MonitorInput` is an :class:`~vibsynth.engine.inputs.InputSource` that picks, in order:

* **JACK** (the host API in use, or a JACK server that answers): a PortAudio input on JACK whose
  ports (``PortAudio:in_N``) a worker thread connects to whatever feeds the system's playback
  ports (``system:playback_N``), excluding vibsynth's own outputs; it looks again every
  ``poll_s`` (never in the audio callback), so new connections are followed as they come and a
  JACK server that comes back is patched again. Needs the JACK-Client package (``jack``): an
  optional import (``pip install 'vibsynth[monitor]'``).
* **PulseAudio / PipeWire**: PortAudio's ALSA ``pulse`` or ``pipewire`` device, recording the
  default output's monitor (``PULSE_SOURCE=@DEFAULT_MONITOR@``).
* **Windows WASAPI**: the first input device PortAudio lists as a ``[Loopback]``.

Where none exists, :meth:`MonitorInput.open` raises one :class:`~vibsynth.errors.DeviceError`
naming what was tried.
"""

from __future__ import annotations

import logging
import os
import re
import threading
from types import ModuleType
from typing import Any

from vibsynth.engine.input_ring import InputRing
from vibsynth.engine.inputs import SoundDeviceInput
from vibsynth.engine.pa_stream import import_sounddevice
from vibsynth.errors import DeviceError

__all__ = ["MONITOR", "MonitorInput", "JackPatcher", "is_monitor_spec"]

log = logging.getLogger(__name__)

#: The ``--follow`` / ``follow.device`` word that asks for the monitor input.
MONITOR = "monitor"
#: Input ports a PortAudio client holds on JACK (``PortAudio``, or ``PortAudio-01`` when taken).
_PA_IN = re.compile(r"^(PortAudio[^:]*):in_(\d+)$")
_PULSE_DEVICES = ("pulse", "pipewire")


def is_monitor_spec(spec: str) -> bool:
    """Whether a ``--follow`` argument asks for the monitor input (``monitor``, any case)."""
    return spec.strip().lower() == MONITOR


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


class JackPatcher:
    """Connects our PortAudio input ports to what feeds ``system:playback_N`` (a worker's job, polled).

    Parameters
    ----------
    channels : int
        Our input ports; playback port ``k`` (0-based) feeds ours ``k mod channels``.
    client_name : str
        The patch-bay client's JACK name.
    """

    def __init__(self, channels: int, client_name: str = "vibsynth-monitor") -> None:
        self.jack = import_jack()
        self.channels = int(channels)
        self.client_name = client_name
        self._client: Any = None
        self._seen: set[str] | None = None
        #: our PortAudio client's input ports, in order (found when they appear)
        self.own: list[str] = []
        #: the ports feeding the system's playback, as connected last
        self.sources: list[str] = []
        self.connections = 0
        self.errors = 0
        self.reason = ""

    def _connect(self) -> Any:
        if self._client is None:
            self._client = self.jack.Client(self.client_name, no_start_server=True)
        return self._client

    def close(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except Exception:  # noqa: BLE001 - a dead server: nothing left to close
                pass

    def _in_ports(self, client: Any) -> set[str]:
        return {p.name for p in client.get_ports(is_audio=True, is_input=True) if _PA_IN.match(p.name)}

    def snapshot(self) -> None:
        """Note the PortAudio input ports there are now: the ones that appear later are ours."""
        try:
            self._seen = self._in_ports(self._connect())
        except Exception as exc:  # noqa: BLE001 - no server yet: every PortAudio port counts as new
            self.reason = f"JACK: {exc}"
            self._seen = set()

    def poll(self) -> None:
        """Find our ports (once they appear), then connect each to every feeder of its playback ports."""
        try:
            self._poll()
        except Exception as exc:  # noqa: BLE001 - the server went away: connect again next time
            self.errors += 1
            self.reason = f"JACK: {exc}"
            self.close()

    def _poll(self) -> None:
        client = self._connect()
        ins = self._in_ports(client)
        if not self.own or not set(self.own) <= ins:
            new = sorted(ins - (self._seen or set()), key=lambda n: int(_PA_IN.match(n).group(2)))  # type: ignore[union-attr]
            owners = {_PA_IN.match(n).group(1) for n in new}  # type: ignore[union-attr]
            self.own = new if len(owners) == 1 and len(new) >= self.channels else []
        self._seen = ins
        if not self.own:
            return
        ours = self.own[0].split(":", 1)[0] + ":"
        wanted: dict[str, set[str]] = {name: set() for name in self.own[: self.channels]}
        playback = client.get_ports(is_audio=True, is_input=True, is_physical=True)
        sources: list[str] = []
        for k, port in enumerate(playback):
            for feeder in client.get_all_connections(port):
                if feeder.name.startswith(ours) or feeder.name.startswith(self.client_name + ":"):
                    continue  # vibsynth's own outputs do not feed its input
                wanted[self.own[k % self.channels]].add(feeder.name)
                sources.append(feeder.name)
        for name, feeders in wanted.items():
            port = client.get_port_by_name(name)
            have = {p.name for p in client.get_all_connections(port)}
            for feeder in sorted(feeders - have):
                client.connect(feeder, name)
                self.connections += 1
            for stale in sorted(have - feeders):  # PortAudio's own link to system:capture, gone sources
                client.disconnect(stale, name)
        self.sources = sorted(set(sources))
        self.reason = ""


class MonitorInput:
    """The system's loopback / monitor as an input (see the module notes).

    Parameters
    ----------
    fs : float
        The engine's rate.
    host_api : str, int or None
        The output's host API (``audio.host_api``): JACK there means the JACK path.
    block_size : int
    channels : int
        Inputs to capture (2: stereo).
    poll_s : float
        How often the JACK worker looks at the graph.
    device_options
        Passed to :class:`~vibsynth.engine.inputs.SoundDeviceInput`.
    """

    def __init__(
        self,
        *,
        fs: float,
        host_api: str | int | None = None,
        block_size: int = 128,
        channels: int = 2,
        poll_s: float = 0.25,
        **device_options: Any,
    ) -> None:
        self._fs = float(fs)
        self.host_api = host_api
        self.block_size = int(block_size)
        self.channels = int(channels)
        self.poll_s = float(poll_s)
        self.device_options = device_options
        self.path = ""  # "JACK", "PulseAudio", "WASAPI loopback" once opened
        self.inner: SoundDeviceInput | None = None
        self.patcher: JackPatcher | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -------------------------------------------------------------- InputSource
    @property
    def fs(self) -> float:
        return self._fs

    @property
    def ring(self) -> InputRing:
        if self.inner is None:
            raise DeviceError("the monitor input is not open yet")
        return self.inner.ring

    def open(self) -> None:
        """Open the first monitor path this system has (raises DeviceError naming what was tried)."""
        sd = import_sounddevice()
        tried: list[str] = []
        for path, attempt in (
            ("JACK", self._open_jack),
            ("PulseAudio/PipeWire", self._open_pulse),
            ("WASAPI loopback", self._open_wasapi),
        ):
            try:
                attempt(sd)
            except DeviceError as exc:
                tried.append(f"{path}: {exc}")
                continue
            self.path = path
            log.info("follow: monitor input via %s", path)
            return
        raise DeviceError("no loopback/monitor input on this system; tried " + "; ".join(tried))

    def _inner(self, spec: str, host_api: str | int | None) -> SoundDeviceInput:
        channels = ",".join(str(c + 1) for c in range(self.channels))
        return SoundDeviceInput(
            f"{spec}:{channels}" if spec else f":{channels}",
            fs=self._fs,
            host_api=host_api,
            block_size=self.block_size,
            **self.device_options,
        )

    def _open_jack(self, sd: ModuleType) -> None:
        names = [str(a["name"]) for a in sd.query_hostapis()]
        if not any("jack" in n.lower() for n in names):
            raise DeviceError("PortAudio has no JACK host API")
        wanted = self.host_api
        if wanted is not None and "jack" not in str(wanted).lower() and not str(wanted).isdigit():
            raise DeviceError(f"the output uses host API {wanted!r}")
        patcher = JackPatcher(self.channels)
        patcher.snapshot()
        if patcher.reason:
            raise DeviceError(patcher.reason)
        inner = self._inner("", "JACK")
        try:
            inner.open()
        except DeviceError:
            patcher.close()
            raise
        self.inner, self.patcher = inner, patcher
        patcher.poll()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vibsynth-monitor", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            if self.patcher is not None:
                self.patcher.poll()

    def _open_pulse(self, sd: ModuleType) -> None:
        names = [str(d["name"]) for d in sd.query_devices() if int(d.get("max_input_channels", 0)) > 0]
        device = next((n for n in names if n.lower() in _PULSE_DEVICES), None)
        if device is None:
            raise DeviceError("PortAudio lists no 'pulse' or 'pipewire' input device")
        os.environ.setdefault("PULSE_SOURCE", "@DEFAULT_MONITOR@")  # libpulse's default source: the monitor
        inner = self._inner(device, None)
        inner.open()
        self.inner = inner

    def _open_wasapi(self, sd: ModuleType) -> None:
        apis = sd.query_hostapis()
        devices = sd.query_devices()
        loopback = [
            i
            for i, d in enumerate(devices)
            if "wasapi" in str(apis[d["hostapi"]]["name"]).lower()
            and "loopback" in str(d["name"]).lower()
            and int(d.get("max_input_channels", 0)) > 0
        ]
        if not loopback:
            raise DeviceError("PortAudio lists no WASAPI [Loopback] input device")
        inner = self._inner(str(loopback[0]), "WASAPI")
        inner.open()
        self.inner = inner

    def close(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)
        if self.inner is not None:
            self.inner.close()
        if self.patcher is not None:
            self.patcher.close()

    def status(self) -> dict[str, Any]:
        status: dict[str, Any] = (
            dict(self.inner.status()) if self.inner is not None else {"state": "closed", "reason": ""}
        )
        status["kind"] = "monitor"
        status["monitor"] = self.path
        if self.patcher is not None:
            status["monitor_sources"] = list(self.patcher.sources)
            status["monitor_connections"] = self.patcher.connections
            status["monitor_errors"] = self.patcher.errors
        feeds = (
            ", ".join(self.patcher.sources) or "nothing playing"
            if self.patcher is not None
            else status.get("device", "")
        )
        status["device"] = f"monitor ({self.path}: {feeds})" if self.path else MONITOR
        return status
