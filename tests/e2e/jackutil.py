"""Shared JACK helpers for end-to-end tests: is a server reachable, capture output ports into numpy.

Usage (typical PortAudio test)::

    require_jack()                       # skip, or fail when VIBSYNTH_E2E_REQUIRED=1
    output.open()                        # PortAudio registers its ports at open ...
    with JackCapture(seconds=2.0) as cap:
        cap.connect(portaudio_output_ports(cap.client)[:1])   # ... connect before start
        output.start()
        cap.arm(); cap.wait()
    x = cap.data[:, 0]                   # float32, shape (frames, n_ports)

:meth:`JackCapture.frame_time_now` and :attr:`JackCapture.start_frame` put
captured samples and events on the same JACK frame clock (for latency).
"""

from __future__ import annotations

import bisect
import os
import re
import subprocess
import threading
from collections.abc import Sequence

import numpy as np
import pytest

__all__ = [
    "E2E_REQUIRED_ENV",
    "e2e_required",
    "jack_server_available",
    "require_jack",
    "JackCapture",
    "JackPlayer",
    "portaudio_output_ports",
    "portaudio_input_ports",
    "jack_ports",
    "new_ports",
    "counter_value",
    "counter_frames",
    "capture",
    "assert_no_collapse",
    "COLLAPSE_FRACTION",
]

E2E_REQUIRED_ENV = "VIBSYNTH_E2E_REQUIRED"


def reclaim_dead_jack_servers() -> list[str]:
    """Free JACK's registry slots of servers that died uncleanly (scripts/jack_reclaim.py); the names freed.

    A killed private server keeps one of the machine's 8 slots; call this before starting one.
    """
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "jack_reclaim.py"
    spec = importlib.util.spec_from_file_location("jack_reclaim", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    freed: list[str] = module.reclaim()
    return freed


def e2e_required() -> bool:
    """True when CI demands the e2e tests run (``VIBSYNTH_E2E_REQUIRED=1``)."""
    return os.environ.get(E2E_REQUIRED_ENV, "") == "1"


def jack_server_available() -> tuple[bool, str]:
    """(reachable, reason): can a JACK client connect to the (default or $JACK_DEFAULT_SERVER) server?"""
    try:
        import jack
    except Exception as exc:  # JACK-Client or libjack missing
        return False, f"JACK-Client is not usable ({exc})"
    try:
        client = jack.Client("vibsynth-probe", no_start_server=True)
    except Exception as exc:
        server = os.environ.get("JACK_DEFAULT_SERVER", "default")
        return False, f"no JACK server '{server}' is running ({exc}); run under scripts/with_jack.sh"
    client.close()
    return True, ""


def require_jack() -> None:
    """Skip the calling test when no JACK server is reachable; fail instead under VIBSYNTH_E2E_REQUIRED=1."""
    import pytest

    ok, reason = jack_server_available()
    if ok:
        return
    if e2e_required():
        pytest.fail(f"{E2E_REQUIRED_ENV}=1 but {reason}")
    pytest.skip(reason)


def portaudio_output_ports(client, pattern: str = "PortAudio") -> list[str]:
    """Names of the audio output ports of PortAudio clients (e.g. ``PortAudio:out_0``), sorted."""
    ports = client.get_ports(name_pattern=pattern, is_audio=True, is_output=True)
    return sorted(p.name for p in ports)


class JackCapture:
    """A JACK client with input ports that records a fixed number of seconds once armed.

    Parameters
    ----------
    seconds : float
        Capacity (and length of a full capture).
    n_ports : int
        Input ports (``in_1`` ..).
    name : str
        JACK client name (made unique per instance).

    Attributes
    ----------
    data : ndarray, shape (frames, n_ports), float32
        The captured samples (valid up to :attr:`frames_captured`).
    start_frame : int or None
        JACK frame time of ``data[0]``.
    gaps : int
        JACK cycles this client missed while recording (its process callback, Python, waited
        for the GIL past a cycle): the capture then lacks those blocks and joins what is
        around them, a hole in the instrument, not in the stream under test.
    rate : int
    """

    _count = 0

    def __init__(self, seconds: float, *, n_ports: int = 1, name: str = "vibsynth-capture") -> None:
        import jack

        JackCapture._count += 1
        # The server named now (tests switch servers within one process): explicit, not cached.
        self.client = jack.Client(
            f"{name}-{os.getpid()}-{JackCapture._count}",
            no_start_server=True,
            servername=os.environ.get("JACK_DEFAULT_SERVER") or None,
        )
        self.rate = int(self.client.samplerate)
        self.inports = [self.client.inports.register(f"in_{k + 1}") for k in range(n_ports)]
        self.data = np.zeros((int(round(seconds * self.rate)), n_ports), dtype=np.float32)
        self.frames_captured = 0
        self.start_frame: int | None = None
        self.gaps = 0
        self._next_frame: int | None = None
        self._blocks: list[tuple[int, int]] = []  # (data index, JACK frame) of each captured block
        self._armed = False
        self._limit = self.data.shape[0]  # frames this capture records (arm(seconds) shortens it)
        self._done = threading.Event()
        self.client.set_process_callback(self._process)
        self.client.activate()

    def _process(self, frames: int) -> None:
        if not self._armed or self._done.is_set():
            return
        pos = self.frames_captured
        n = min(frames, self._limit - pos)
        now = self.client.last_frame_time
        if pos == 0:
            self.start_frame = now
        elif now != self._next_frame:
            self.gaps += 1
        self._next_frame = now + frames
        self._blocks.append((pos, now))
        for k, port in enumerate(self.inports):
            self.data[pos : pos + n, k] = port.get_array()[:n]
        self.frames_captured = pos + n
        if self.frames_captured >= self._limit:
            self._done.set()

    def connect(self, sources: Sequence[str]) -> None:
        """Connect output ports (by name) to this client's inputs, in order."""
        if len(sources) > len(self.inports):
            raise ValueError(f"{len(sources)} sources for {len(self.inports)} capture ports")
        for src, dst in zip(sources, self.inports):
            self.client.connect(src, dst)

    def reset(self) -> None:
        """Forget the capture and stop recording (arm again to record anew)."""
        self._armed = False
        self._done.clear()
        self.frames_captured = 0
        self.start_frame = None
        self.gaps = 0
        self._next_frame = None
        self._blocks = []

    def arm(self, seconds: float | None = None) -> None:
        """Start recording at the next JACK cycle: ``seconds`` (at most the capacity; None = all of it)."""
        capacity = self.data.shape[0]
        self._limit = capacity if seconds is None else max(1, min(capacity, int(round(seconds * self.rate))))
        self._armed = True

    def index_of(self, frame: int) -> int:
        """Index in :attr:`data` of the sample of JACK frame ``frame``; gap-aware.

        Where cycles were missed (:attr:`gaps`) the data joins what is around them, so
        ``frame - start_frame`` would point past the sample; a frame in a missed cycle maps
        to the first sample captured after it.
        """
        blocks = self._blocks
        k = bisect.bisect_right([f for _, f in blocks], frame) - 1
        if k < 0:
            return 0
        pos, start = blocks[k]
        end = blocks[k + 1][0] if k + 1 < len(blocks) else self.frames_captured
        return min(pos + (frame - start), end)

    def frame_of(self, index: int) -> int:
        """The JACK frame of :attr:`data`'s sample ``index`` (the inverse of :meth:`index_of`)."""
        k = bisect.bisect_right([p for p, _ in self._blocks], index) - 1
        pos, start = self._blocks[max(k, 0)]
        return start + (index - pos)

    def frame_time_now(self) -> int:
        """The JACK frame clock now (same clock as :attr:`start_frame`)."""
        return int(self.client.frame_time)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until full (True) or timeout (False)."""
        if timeout is None:
            timeout = self._limit / self.rate + 10.0
        return self._done.wait(timeout)

    def close(self) -> None:
        try:
            self.client.deactivate()
        finally:
            self.client.close()

    def __enter__(self) -> JackCapture:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def capture(sources: Sequence[str], seconds: float) -> tuple[np.ndarray, int]:
    """Record ``seconds`` from output ports now; returns (data (frames, n), rate)."""
    with JackCapture(seconds, n_ports=len(sources)) as cap:
        cap.connect(sources)
        cap.arm()
        if not cap.wait():
            raise TimeoutError("JACK capture did not complete (is the server running in real time?)")
        return cap.data.copy(), cap.rate


#: Marker for real-time checks (run once, no reruns: the audio callback is compiled and never
#: waits for the GIL, so a failure is a defect). Each asserts only a collapse
#: (:func:`assert_no_collapse`), never an absolute time.
REALTIME = pytest.mark.realtime

#: The largest share of a window's callbacks a test lets underflow. PortAudio counts every xrun
#: of the JACK server as an underflow, the dummy driver's own late wake-ups included: on the
#: shared 2-core VMs of this kind that noise reached 11 in 10 s (about 0.3 % of the 3,750
#: callbacks) under a 10,000 messages/s flood, and 0-3 in 10 s quiet (docs/engine.md,
#: "Whose underflows?", benchmarks/bench_rt_share.py). A test asserts only what is ten times
#: beyond that, a collapse (a callback that waits on a lock, an engine that stopped keeping up:
#: such defects underflowed in most callbacks, >1000 in 10 s); the distributions themselves are
#: the benchmarks' job.
COLLAPSE_FRACTION = 0.05


def assert_no_collapse(underflows: int, seconds: float, what: str, *, rate: int = 48000, block: int = 128) -> None:
    """Fail when more than :data:`COLLAPSE_FRACTION` of the callbacks of ``seconds`` underflowed.

    Parameters
    ----------
    underflows : int
        Underflows counted over the window(s).
    seconds : float
        The window(s)' total length.
    what : str
        What ran during the window(s), for the message.
    """
    callbacks = seconds * rate / block
    limit = COLLAPSE_FRACTION * callbacks
    assert underflows <= limit, (
        f"{what}: {underflows} underflows in {seconds:g} s ({callbacks:.0f} callbacks), more than "
        f"{100 * COLLAPSE_FRACTION:g} % of them: the audio collapsed (the machine's own noise is below 0.5 %)"
    )


def portaudio_input_ports(client, pattern: str = "PortAudio") -> list[str]:
    """Names of the audio input ports of PortAudio clients (e.g. ``PortAudio:in_0``), in port order."""
    ports = client.get_ports(name_pattern=pattern, is_audio=True, is_input=True)
    return sorted((p.name for p in ports), key=lambda name: (len(name), name))


def jack_ports() -> set[str]:
    """Every port of the JACK server now (``jack_lsp``: no JACK client in the test process)."""
    return set(subprocess.run(["jack_lsp"], capture_output=True, text=True, check=True).stdout.split())


def new_ports(before: set[str], kind: str = "in") -> list[str]:
    """PortAudio's ``in`` (or ``out``) ports that appeared since ``before``, in port order.

    Any PortAudio client counts (``PortAudio[^:]*``): a process that initialised PortAudio on JACK
    holds the client name ``PortAudio`` for as long as it lives (the test process itself, after an
    in-process output test), so a serve started later is ``PortAudio-01``.
    """
    fresh = [p for p in jack_ports() - before if re.fullmatch(rf"PortAudio[^:]*:{kind}_\d+", p)]
    return sorted(fresh, key=lambda name: (len(name), name))


#: Period of :func:`counter_value`: frames that the counter signal encodes before it wraps.
COUNTER_PERIOD = 1 << 16


def counter_value(frames: np.ndarray, port: int = 0) -> np.ndarray:
    """The counter signal :class:`JackPlayer` plays: ``((frame + 4096 port) mod 2**16) / 2**16 - 0.5``.

    Exact in float32, so a received sample names the JACK frame it was played on (modulo 2**16),
    and each port's differs.
    """
    k = (np.asarray(frames, dtype=np.int64) + 4096 * port) % COUNTER_PERIOD
    return (k / COUNTER_PERIOD - 0.5).astype(np.float32)


def counter_frames(values: np.ndarray, port: int = 0) -> np.ndarray:
    """The JACK frames (mod 2**16) that :func:`counter_value` samples encode."""
    k = np.round((np.asarray(values, dtype=np.float64) + 0.5) * COUNTER_PERIOD).astype(np.int64)
    return (k - 4096 * port) % COUNTER_PERIOD


class JackPlayer:
    """A JACK client whose output ports play a known signal: anything can be connected to them.

    Each port ``k`` plays :func:`counter_value` of the JACK frame time of every sample
    (``signal=None``), or a fixed array (``signal`` of shape (frames, n_ports), then zeros),
    started by :meth:`play` at the next cycle.

    Attributes
    ----------
    gaps : int
        JACK cycles this (Python) client missed while playing: those cycles' samples were not
        written (a hole in the instrument, not in what is under test).
    start_frame : int or None
        JACK frame time of the first sample of ``signal`` (after :meth:`play`).
    """

    _count = 0

    def __init__(self, *, n_ports: int = 1, signal: np.ndarray | None = None, name: str = "vibsynth-player") -> None:
        import jack

        JackPlayer._count += 1
        self.client = jack.Client(
            f"{name}-{os.getpid()}-{JackPlayer._count}",
            no_start_server=True,
            servername=os.environ.get("JACK_DEFAULT_SERVER") or None,
        )
        self.rate = int(self.client.samplerate)
        self.outports = [self.client.outports.register(f"out_{k + 1}") for k in range(n_ports)]
        self.signal = None if signal is None else np.asarray(signal, dtype=np.float32).reshape(-1, n_ports)
        self.position = 0
        self.start_frame: int | None = None
        self.gaps = 0
        self._next_frame: int | None = None
        self._playing = False
        self.client.set_process_callback(self._process)
        self.client.activate()

    def _process(self, frames: int) -> None:
        now = self.client.last_frame_time
        if self._next_frame is not None and now != self._next_frame and self._playing:
            self.gaps += 1
        self._next_frame = now + frames
        for k, port in enumerate(self.outports):
            out = port.get_array()
            if not self._playing:
                out[:] = 0.0
            elif self.signal is None:
                out[:] = counter_value(np.arange(now, now + frames), k)
            else:
                pos = self.position
                n = max(0, min(frames, self.signal.shape[0] - pos))
                out[:n] = self.signal[pos : pos + n, k]
                out[n:] = 0.0
        if self._playing and self.signal is not None:
            if self.start_frame is None:
                self.start_frame = now
            self.position += frames

    def connect(self, targets: Sequence[str]) -> None:
        """Connect this client's outputs, in order, to input ports (by name)."""
        for port, dst in zip(self.outports, targets):
            self.client.connect(port, dst)

    def play(self) -> None:
        self._playing = True

    def close(self) -> None:
        try:
            self.client.deactivate()
        finally:
            self.client.close()

    def __enter__(self) -> JackPlayer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_PLAYER_CHILD = r"""
import sys
import numpy as np
from tests.e2e.jackutil import JackPlayer

signal = np.load(sys.argv[1])
with JackPlayer(n_ports=signal.shape[1], signal=signal) as player:
    player.connect(sys.argv[2:])
    player.play()
    print("playing", flush=True)
    sys.stdin.read()  # until the parent closes stdin
print(f"gaps {player.gaps}", flush=True)
"""


class JackPlayerProcess:
    """A :class:`JackPlayer` of ``signal`` (shape (frames, n_ports)) in a child process, playing into ``targets``.

    On a synchronous JACK graph (``scripts/with_jack.sh``) a late client makes every cycle late:
    a Python client in the test process waits for the GIL whenever the test's own thread runs,
    and its lateness would be counted as the tested stream's underflows. In its own process it
    waits for nobody. :attr:`gaps` (after :meth:`close`) counts the cycles it still missed.
    """

    def __init__(self, signal: np.ndarray, targets: Sequence[str], folder: os.PathLike[str] | str) -> None:
        import sys
        from pathlib import Path

        path = Path(folder) / f"player-{os.getpid()}-{id(self)}.npy"
        np.save(path, np.asarray(signal, dtype=np.float32).reshape(len(signal), -1))
        root = Path(__file__).resolve().parents[2]
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _PLAYER_CHILD, str(path), *targets],
            cwd=root,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if line.strip() != "playing":
            self.close()
            raise AssertionError(f"the player process did not start: {line!r}")
        self.gaps = -1

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                out, _ = self.proc.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                out, _ = self.proc.communicate()
            words = out.split()
            self.gaps = int(words[-1]) if len(words) >= 2 and words[-2] == "gaps" else -1

    def __enter__(self) -> JackPlayerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
