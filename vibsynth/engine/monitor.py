"""``--follow monitor``: follow what the system plays (a loopback / monitor input), where it has one.

:class:`MonitorInput` is an :class:`~vibsynth.engine.inputs.InputSource` that picks, in order:

* **JACK** (the host API in use, or a JACK server that answers): a PortAudio input on JACK whose
  ports (``PortAudio:in_N``) a patch bay connects to whatever feeds the system's playback
  ports (``system:playback_N``), excluding vibsynth's own outputs; it looks again every
  ``poll_s`` (never in the audio callback), so new connections are followed as they come. The
  patch bay is a child process (:mod:`vibsynth.engine.monitor_patchbay`: a JACK client must not
  outlive its server in serve's process) started again when it ends, so a JACK server that
  comes back is patched again. It needs the JACK-Client package (``jack``), imported in the child
  only (``pip install 'vibsynth[monitor]'``; without it, one message says so).
* **PulseAudio / PipeWire**: PortAudio's ALSA ``pulse`` or ``pipewire`` device, recording the
  default output's monitor (``PULSE_SOURCE=@DEFAULT_MONITOR@``).
* **Windows WASAPI**: the first input device PortAudio lists as a ``[Loopback]``.

Where none exists, :meth:`MonitorInput.open` raises one :class:`~vibsynth.errors.DeviceError`
naming what was tried.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Callable
from types import ModuleType
from typing import Any

from vibsynth.engine.input_ring import InputRing
from vibsynth.engine.inputs import SoundDeviceInput
from vibsynth.engine.pa_stream import import_sounddevice
from vibsynth.errors import DeviceError

__all__ = ["MONITOR", "MonitorInput", "PatchBay", "is_monitor_spec"]

log = logging.getLogger(__name__)

#: The ``--follow`` / ``follow.device`` word that asks for the monitor input.
MONITOR = "monitor"
_PULSE_DEVICES = ("pulse", "pipewire")


def is_monitor_spec(spec: str) -> bool:
    """Whether a ``--follow`` argument asks for the monitor input (``monitor``, any case)."""
    return spec.strip().lower() == MONITOR


class PatchBay:
    """The JACK patch bay child (:mod:`vibsynth.engine.monitor_patchbay`), started again whenever it ends.

    Parameters
    ----------
    channels : int
    poll_s : float
        The child's polling period; a child that ended is started again after ``4 poll_s``.
    """

    def __init__(self, channels: int, poll_s: float = 0.25) -> None:
        self.channels = int(channels)
        self.poll_s = float(poll_s)
        self.own: list[str] = []
        self.sources: list[str] = []
        self.connections = 0
        self.starts = 0
        self.reason = ""
        self._done_connections = 0
        self._proc: subprocess.Popen[str] | None = None
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _spawn(self) -> None:
        cmd = [
            sys.executable,
            "-m",
            "vibsynth.engine.monitor_patchbay",
            "--channels",
            str(self.channels),
            "--parent",
            str(os.getpid()),
            "--poll",
            str(self.poll_s),
            "--own",
            ",".join(self.own),
        ]
        self._done_connections += self.connections if self.starts else 0
        self.connections = 0
        self._ready.clear()
        self._proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.starts += 1
        threading.Thread(target=self._read, args=(self._proc,), name="vibsynth-monitor-read", daemon=True).start()

    def _read(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            try:
                message = json.loads(line)
            except ValueError:
                continue
            if "error" in message:
                self.reason = str(message["error"])
            if message.get("ready"):
                self.reason = ""
                self._ready.set()
            if "own" in message:
                self.own = list(message["own"])
                self.sources = list(message["sources"])
                self.connections = int(message["connections"])
        proc.wait()
        self._ready.set()  # an early exit wakes start()

    def start(self, timeout: float = 10.0) -> None:
        """Start the child and wait until it noted the ports there are (raises DeviceError with its reason)."""
        self._spawn()
        self._ready.wait(timeout)
        assert self._proc is not None
        if self._proc.poll() is not None or not self._ready.is_set():
            self.close()
            raise DeviceError(self.reason or "the JACK patch bay did not start")
        self._stop.clear()
        self._thread = threading.Thread(target=self._watch, name="vibsynth-monitor", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.wait(4 * self.poll_s):
            if self._proc is not None and self._proc.poll() is not None:
                self._spawn()  # the server went (and maybe came back): patch it again

    @property
    def total_connections(self) -> int:
        return self._done_connections + self.connections

    def close(self) -> None:
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)
        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


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
    device_input : callable
        Makes the PortAudio input from a spec, ``fs``, ``host_api``, ``block_size`` and
        ``device_options`` (default :class:`~vibsynth.engine.inputs.SoundDeviceInput`; tests pass a stand-in).
    device_options
        Passed to ``device_input``.
    """

    def __init__(
        self,
        *,
        fs: float,
        device_input: Callable[..., SoundDeviceInput] = SoundDeviceInput,
        host_api: str | int | None = None,
        block_size: int = 128,
        channels: int = 2,
        poll_s: float = 0.25,
        **device_options: Any,
    ) -> None:
        self._fs = float(fs)
        self.device_input = device_input
        self.host_api = host_api
        self.block_size = int(block_size)
        self.channels = int(channels)
        self.poll_s = float(poll_s)
        self.device_options = device_options
        self.path = ""  # "JACK", "PulseAudio", "WASAPI loopback" once opened
        self.inner: SoundDeviceInput | None = None
        self.patcher: PatchBay | None = None

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
        return self.device_input(
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
        patchbay = PatchBay(self.channels, self.poll_s)
        patchbay.start()  # it notes the ports there are: the input's, opened next, are ours
        inner = self._inner("", "JACK")
        try:
            inner.open()
        except DeviceError:
            patchbay.close()
            raise
        self.inner, self.patcher = inner, patchbay

    def _open_pulse(self, sd: ModuleType) -> None:
        found = [
            i
            for i, d in enumerate(sd.query_devices())
            if str(d["name"]).lower() in _PULSE_DEVICES and int(d.get("max_input_channels", 0)) > 0
        ]
        if not found:
            raise DeviceError("PortAudio lists no 'pulse' or 'pipewire' input device")
        os.environ.setdefault("PULSE_SOURCE", "@DEFAULT_MONITOR@")  # libpulse's default source: the monitor
        inner = self._inner(str(found[0]), None)  # by index: a name substring may match several
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
            status["monitor_connections"] = self.patcher.total_connections
            status["monitor_patchbay_starts"] = self.patcher.starts
        feeds = (
            ", ".join(self.patcher.sources) or "nothing playing"
            if self.patcher is not None
            else status.get("device", "")
        )
        status["device"] = f"monitor ({self.path}: {feeds})" if self.path else MONITOR
        return status
