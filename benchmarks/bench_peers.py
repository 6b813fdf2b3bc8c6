#!/usr/bin/env python3
"""Peers benchmark (issue 12): vibsynth against scsynth and pyo on the same job.

    python benchmarks/bench_peers.py                          # all three, ~8 min
    python benchmarks/bench_peers.py --idle-trials 200 --trials 0 --seconds 2   # a quick look
    python benchmarks/bench_peers.py --only scsynth,pyo --trials 20 --json /tmp/p.json
    python benchmarks/bench_peers.py --vibsynth-rev HEAD      # vibsynth of the last commit, not the tree
    python benchmarks/bench_peers.py --vibsynth-src /tmp/vs   # vibsynth from a built source folder
    python benchmarks/bench_peers.py --vibsynth-ref /tmp/old  # + a second vibsynth, interleaved (before/after)

No wrapper is needed: every peer gets its own private JACK server on the dummy driver
(``jackd -n bench-peers-<peer> -R -d dummy -r 48000 -p 128``, without ``-R`` when real-time
scheduling is refused; ``JACK_NO_AUDIO_RESERVATION=1``), started and stopped by this script.
The peers run at the same time, each on its own server; the JACK clients that watch and
record a server live in a child process per server (``_jack_agent``: libjack serves one
server per process). Needs jackd2 and the JACK-Client module (both already needed by the e2e
tests); a peer that is not installed is skipped with a message (scsynth: Debian
``supercollider-server``; pyo: ``pip install pyo`` into the venv).

The job, one channel, 48 kHz, JACK period 128:

* **scsynth** (Debian ``supercollider-server``): a SynthDef built here in Python (SynthDef
  file format version 2, no sclang needed), sent with ``/d_recv``: ``WhiteNoise`` through 30
  ``BPF`` (centres 10*100^(k/29) Hz, k = 0..29, rq = bandwidth between the geometric
  midpoints / centre = 0.159), each times its gain control ``g0``..``g29`` (``MulAdd``
  chain), times a master ``amp``, to ``Out`` bus 0. Started with ``/s_new``; driven with
  ``/n_set``/``/n_setn`` over OSC UDP.
* **pyo** (PyPI ``pyo``, ``Server(audio='jack')`` in a child process): ``Noise()`` through 30
  ``ButBP`` (same centres, q = 1/rq), gains from an ``OscReceive`` (``/peer/g/<k>``,
  ``/peer/amp``, interpolation off), summed with ``Mix``. pyo reads its OSC socket (liblo,
  non-blocking) at the start of every audio callback, in the audio thread.
* **vibsynth**: ``.venv/bin/vibsynth serve --output sounddevice`` with ``audio.host_api: JACK``
  (PortAudio's JACK host API), block 128; glide 0. It renders the texture from its precomputed
  noise bank (no filtering at run time), so its audio work is not the peers' 30 filters: the
  comparison is of the whole job (same texture, same control traffic), not of one algorithm.
  ``--vibsynth-rev REV`` runs ``git archive REV`` (C core built in a temporary folder) instead
  of the working tree.

The peers' band gains are set over OSC to the default basis' mean spectrum M (a constant-Q
band-pass on white noise has power proportional to its bandwidth, so the gain in dB is
M_k - 10 log10(f_k / f_0), normalised to a maximum of 1): approximately vibsynth's texture at
balance 0. The per-sample work does not depend on the gains.

All peers start, then, every peer streaming all along:

* **idle**: per peer in turn, ``--seconds`` of streaming at a steady loud level, no control
  traffic; then the idle latency trials of all peers **interleaved**: ``--idle-trials`` (800)
  rounds, each one trial of every peer in a fresh random order, so machine load (the VM is
  shared) hits every peer alike;
* **flood**: per peer in turn, ``--seconds`` of measurement then ``--trials`` (50) latency
  trials under the flood:
* **flood**: a separate sender process sends ``--rate`` (10,000) OSC messages/s over UDP to the
  target, in 1 ms bursts: scsynth ``/n_set <node> "g<k>" <v>``, pyo ``/peer/g/<k> f <v>``
  (k cycling over the 30 bands, values alternating), vibsynth ``/vibsynth/balance f <v>``
  (alternating; the spectral-shape knob, as the band gains are for the peers; ``--vibsynth-flood
  texture|intensity`` sends ``/vibsynth/texture ff`` / ``/vibsynth/intensity f`` instead, but
  those also set the level, so no latency is measured under them). The flood keeps running
  during the latency trials.

Measures, per phase:

* **CPU %**: utime + stime of the target process (all its threads) from /proc/PID/stat over
  the measurement window, in % of one core. Also jackd's, the sender's and the whole machine's.
* **DSP %**: JACK's own load figure (``jack_cpu_load``, whole graph), mean and max of samples
  taken every 0.25 s.
* **xruns**: cycles in which jackd reports the target's JACK client late ("JackEngine::XRun:
  client = <target> was not finished" lines in jackd's log) over the whole phase (window +
  trials); also the server's xrun callbacks (any client) and the dummy driver's own late
  wake-ups, and the same counts for ``--baseline`` seconds of the server alone before the target
  starts. For vibsynth also ``underflows`` from ``/vibsynth/status`` over the window (PortAudio
  flags every xrun of the server, including the capture client's during the trials).
* **latency**: as benchmarks/bench_osc.py: a JACK client on the same server records the
  target's output port; each trial sends "silence" (amp 0 / intensity 0), waits ``--gap``
  (0.05 s), notes the time, sends "loud", waits ``--gap``; latency = time of the first
  captured sample with |x| > 1e-7 minus the send time. A message waits for the target's next
  cycle, a wait uniform over one period (2.67 ms), so a median of n trials is known to about
  +-1.96 x 2.67 / (2 sqrt(n)) ms (95 %): +-0.48 ms for 30 trials, +-0.09 ms for 800. The idle
  trials therefore (``--phase stratified``) send at a chosen fraction of the cycle before a cycle
  start (predicted from the capture's last cycle), the same fraction for every peer of a round
  and the rounds' fractions spread evenly over the cycle: the wait, the same for any engine,
  then cancels out of the comparison. Each trial also records ``wait`` (send -> the next cycle
  start, measured) and which cycle took the message (the one running at the send, the next, or
  a later one: missed), and ``excess`` = latency - wait: an engine that applies every message
  at the next cycle start has excess 0; a receive thread that wakes too late for it misses a
  cycle (excess one period). Printed: per peer the median with its 95 % order-statistic
  interval; vibsynth's median over the better peer's (the lower median) as a ratio and a
  difference, and the difference of mean excess, with 95 % intervals from a bootstrap that
  resamples whole rounds (peers paired by round, so shared load stays paired). Times are
  CLOCK_MONOTONIC (each captured sample gets the actual start time of its JACK cycle, from
  ``frames_since_cycle_start``, plus its offset); the JACK frame clock of bench_osc.py is also
  recorded (``--latency-clock frame``), but its estimate ``jack_frame_time()`` drifts by tens
  of ms after the dummy driver wakes late, which happens on a busy VM. A trial can be <= 0
  when the target's cycle ran late and still took a message sent after that cycle's nominal
  start.
* **load**: the load average and the whole machine's busy % over the interleaved trials (and
  per round), in the table and the JSON.

Prints tables and writes JSON (machine, JACK settings, versions, every idle trial) to
benchmarks/results/peers.json. With ``--only``, the other peers' entries already in that file
are kept (each entry has its own date and machine info); ``--no-merge`` drops them.

The run is bounded (``--timeout``, default from the phase lengths) and every process it starts
(jackd, scsynth, the pyo child, vibsynth serve, the flood sender) is stopped on exit, on Ctrl-C,
on SIGTERM and on the timeout; the children also get SIGTERM from the kernel if this script
dies (``setpriv --pdeathsig``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from peers_stats import median_ci, paired_bootstrap, round_matrix

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_JSON = ROOT / "benchmarks" / "results" / "peers.json"
PEERS = ("scsynth", "pyo", "vibsynth")

# ------------------------------------------------------------------ the texture (30 bands)
N_BANDS = 30
CENTRES = [10.0 * 100.0 ** (k / (N_BANDS - 1)) for k in range(N_BANDS)]
_R = 100.0 ** (1.0 / (N_BANDS - 1))  # ratio between adjacent centres
RQ = math.sqrt(_R) - 1.0 / math.sqrt(_R)  # (upper - lower midpoint) / centre = 0.159
SILENT_THRESHOLD = 1e-7
SC_NODE = 1000
SC_DEF_NAME = "vibsynth_peer_bands"
PYO_AMP = "/peer/amp"
PYO_GAIN = "/peer/g/{}"


def band_gains() -> tuple[list[float], str]:
    """Linear gains of the 30 band-passes approximating vibsynth's mean spectrum M (max 1)."""
    try:
        sys.path.insert(0, str(ROOT))
        from vibsynth.formats.basis_file import default_basis

        basis = default_basis()
        centres = np.asarray(basis.centres_hz, dtype=float)
        mean_db = np.asarray(basis.mean_db, dtype=float)
        if centres.shape != (N_BANDS,) or not np.allclose(centres, CENTRES, rtol=1e-3):
            raise ValueError(f"basis centres differ from 10*100^(k/29): {centres}")
        db = mean_db - 10.0 * np.log10(centres / centres[0])
        return [float(g) for g in 10.0 ** ((db - db.max()) / 20.0)], "default basis mean spectrum M"
    except Exception as exc:  # the benchmark still runs (flat gains) if the package is mid-edit
        return [1.0] * N_BANDS, f"flat (default basis unavailable: {exc})"


# ------------------------------------------------------------------ OSC (minimal, written here)
def _osc_str(s: str) -> bytes:
    b = s.encode("utf-8") + b"\0"
    return b + b"\0" * (-len(b) % 4)


def osc_message(address: str, *args) -> bytes:
    """Encode an OSC 1.0 message; int -> i, float -> f, str -> s, bytes -> b."""
    tags, data = ",", b""
    for a in args:
        if isinstance(a, bool):
            raise TypeError("bool")
        if isinstance(a, int):
            tags += "i"
            data += struct.pack(">i", a)
        elif isinstance(a, float):
            tags += "f"
            data += struct.pack(">f", a)
        elif isinstance(a, str):
            tags += "s"
            data += _osc_str(a)
        elif isinstance(a, (bytes, bytearray)):
            tags += "b"
            data += struct.pack(">i", len(a)) + bytes(a) + b"\0" * (-len(a) % 4)
        else:
            raise TypeError(f"cannot encode {a!r}")
    return _osc_str(address) + _osc_str(tags) + data


def osc_decode(packet: bytes) -> tuple[str, list]:
    """Decode one OSC message (not bundles): (address, args)."""

    def read_str(pos: int) -> tuple[str, int]:
        end = packet.index(b"\0", pos)
        return packet[pos:end].decode("utf-8", "replace"), (end + 4) & ~3

    address, pos = read_str(0)
    if pos >= len(packet):
        return address, []
    tags, pos = read_str(pos)
    args: list = []
    for t in tags[1:]:
        if t == "i":
            args.append(struct.unpack_from(">i", packet, pos)[0])
            pos += 4
        elif t == "f":
            args.append(struct.unpack_from(">f", packet, pos)[0])
            pos += 4
        elif t == "h":
            args.append(struct.unpack_from(">q", packet, pos)[0])
            pos += 8
        elif t == "d":
            args.append(struct.unpack_from(">d", packet, pos)[0])
            pos += 8
        elif t in "sS":
            s, pos = read_str(pos)
            args.append(s)
        elif t == "b":
            n = struct.unpack_from(">i", packet, pos)[0]
            args.append(packet[pos + 4 : pos + 4 + n])
            pos += 4 + n + (-n % 4)
        elif t in "TF":
            args.append(t == "T")
        elif t == "N":
            args.append(None)
        else:
            break
    return address, args


class OscClient:
    """A UDP socket bound to localhost, talking to one server (replies come back to it)."""

    def __init__(self, port: int) -> None:
        self.target = ("127.0.0.1", port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))

    def send(self, packet: bytes) -> None:
        self.sock.sendto(packet, self.target)

    def request(self, packet: bytes, expect: str, timeout: float = 2.0) -> list:
        """Send, then wait for a reply with address ``expect``; its args."""
        self.send(packet)
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no {expect} reply")
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                raise TimeoutError(f"no {expect} reply") from None
            except ConnectionRefusedError:
                time.sleep(min(0.05, max(0.0, deadline - time.monotonic())))
                continue
            address, args = osc_decode(data)
            if address == expect:
                return args
            if address in ("/fail", "/vibsynth/error"):
                raise RuntimeError(f"{address} {args}")

    def close(self) -> None:
        self.sock.close()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ------------------------------------------------------------------ SynthDef v2 (written here)
SCALAR, CONTROL, AUDIO = 0, 1, 2


class SynthDefV2:
    """A tiny encoder of SuperCollider's SynthDef file format, version 2 ("SCgf").

    Inputs of :meth:`ugen` are numbers (constants) or ``(ugen_index, output_index)``.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.constants: list[float] = []
        self.params: list[tuple[str, float]] = []
        self.ugens: list[tuple[str, int, list[tuple[int, int]], list[int], int]] = []

    def const(self, value: float) -> tuple[int, int]:
        value = float(np.float32(value))
        if value not in self.constants:
            self.constants.append(value)
        return (-1, self.constants.index(value))

    def param(self, name: str, default: float) -> int:
        self.params.append((name, float(default)))
        return len(self.params) - 1

    def ugen(self, cls: str, rate: int, inputs: list, outputs: list[int], special: int = 0) -> int:
        spec = [self.const(i) if isinstance(i, (int, float)) else (int(i[0]), int(i[1])) for i in inputs]
        for src, _ in spec:
            if src >= len(self.ugens):
                raise ValueError("ugens must be added in topological order")
        self.ugens.append((cls, rate, spec, list(outputs), special))
        return len(self.ugens) - 1

    @staticmethod
    def _pstr(s: str) -> bytes:
        b = s.encode("ascii")
        return struct.pack(">B", len(b)) + b

    def encode(self) -> bytes:
        out = [b"SCgf", struct.pack(">iH", 2, 1), self._pstr(self.name)]
        out.append(struct.pack(">i", len(self.constants)))
        out += [struct.pack(">f", c) for c in self.constants]
        out.append(struct.pack(">i", len(self.params)))
        out += [struct.pack(">f", v) for _, v in self.params]
        out.append(struct.pack(">i", len(self.params)))
        for k, (name, _) in enumerate(self.params):
            out += [self._pstr(name), struct.pack(">i", k)]
        out.append(struct.pack(">i", len(self.ugens)))
        for cls, rate, inputs, outputs, special in self.ugens:
            out += [self._pstr(cls), struct.pack(">biih", rate, len(inputs), len(outputs), special)]
            out += [struct.pack(">ii", src, idx) for src, idx in inputs]
            out += [struct.pack(">b", r) for r in outputs]
        out.append(struct.pack(">H", 0))  # no variants
        return b"".join(out)


def peer_synthdef() -> bytes:
    """WhiteNoise -> 30 BPF, each times its gain control, summed, times amp, to Out bus 0."""
    sd = SynthDefV2(SC_DEF_NAME)
    sd.param("amp", 0.0)
    for k in range(N_BANDS):
        sd.param(f"g{k}", 0.0)
    ctl = sd.ugen("Control", CONTROL, [], [CONTROL] * (1 + N_BANDS), special=0)
    noise = sd.ugen("WhiteNoise", AUDIO, [], [AUDIO])
    acc = None
    for k, f in enumerate(CENTRES):
        bpf = sd.ugen("BPF", AUDIO, [(noise, 0), f, RQ], [AUDIO])
        acc = sd.ugen("MulAdd", AUDIO, [(bpf, 0), (ctl, 1 + k), 0.0 if acc is None else (acc, 0)], [AUDIO])
    out = sd.ugen("BinaryOpUGen", AUDIO, [(acc, 0), (ctl, 0)], [AUDIO], special=2)  # 2 = '*'
    sd.ugen("Out", AUDIO, [0.0, (out, 0)], [])
    return sd.encode()


# ------------------------------------------------------------------ child processes
_CHILDREN: list[subprocess.Popen] = []


def spawn(cmd: list[str], *, env: dict, log: Path, stdout=None, stdin=None, cwd: Path = ROOT) -> subprocess.Popen:
    """Start a child in its own session (Ctrl-C reaches only us; we stop it in order) that
    also gets SIGTERM if this process dies without cleaning up (setpriv --pdeathsig)."""
    if shutil.which("setpriv"):
        cmd = ["setpriv", "--pdeathsig", "TERM", "--", *cmd]
    fh = open(log, "ab")
    proc = subprocess.Popen(
        cmd, env=env, stdout=stdout or fh, stderr=fh, stdin=stdin or subprocess.DEVNULL, start_new_session=True, cwd=cwd
    )
    fh.close()
    _CHILDREN.append(proc)
    return proc


def stop(proc: subprocess.Popen | None, timeout: float = 10.0) -> None:
    """SIGTERM, then SIGKILL after ``timeout``: only this process, by its id."""
    if proc is None:
        return
    if proc.poll() is None:
        try:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        except ProcessLookupError:
            pass
    if proc in _CHILDREN:
        _CHILDREN.remove(proc)


def stop_all() -> None:
    for proc in reversed(list(_CHILDREN)):  # newest first: targets and senders before jackd
        try:
            stop(proc, timeout=5.0)
        except Exception as exc:  # keep going: every child must be stopped
            print(f"bench_peers: could not stop pid {proc.pid}: {exc}", file=sys.stderr)


class JackServer:
    """A private jackd on the dummy driver (``-R`` first, then without).

    The name is fixed per peer (``bench-peers-<peer>``; with the pid appended only when a live
    server already has it): JACK's server registry (/dev/shm/jack-shm-registry) has 8 slots and
    reclaims a dead server's slot only for a new server of the same name, so unique names
    would leak a slot whenever a jackd dies without unregistering.
    """

    def __init__(self, name: str, rate: int, period: int, logdir: Path, driver_args: tuple[str, ...] = ()) -> None:
        if _server_running(name):
            name = f"{name}-{os.getpid()}"
        self.name, self.rate, self.period = name, rate, period
        self.driver_args = driver_args  # more dummy-driver options, e.g. ("-P", "16") playback ports
        self.log = logdir / f"jackd-{name}.log"
        self.env = dict(os.environ, JACK_DEFAULT_SERVER=name, JACK_NO_AUDIO_RESERVATION="1")
        self.proc: subprocess.Popen | None = None
        self.realtime = False

    def start(self) -> None:
        for realtime in (True, False):
            cmd = (
                ["jackd", "-n", self.name]
                + (["-R"] if realtime else [])
                + ["-d", "dummy", "-r", str(self.rate), "-p", str(self.period), *self.driver_args]
            )
            self.proc = spawn(cmd, env=self.env, log=self.log)
            ok = (
                subprocess.run(
                    ["jack_wait", "-w", "-t", "10"],
                    env=self.env,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    timeout=20,
                ).returncode
                == 0
            )
            if ok and self.proc.poll() is None:
                self.realtime = realtime
                return
            stop(self.proc)
            if "Too many servers" in self.log_text():
                raise RuntimeError(
                    "jackd: 'Too many servers already active': JACK's registry "
                    "(/dev/shm/jack-shm-registry, 8 slots) is full; a slot of a dead server is "
                    "reclaimed by starting and stopping (SIGTERM) a jackd of the same name"
                )
        raise RuntimeError(f"jackd did not start; log:\n{self.log.read_text(errors='replace')}")

    def log_text(self) -> str:
        try:
            return self.log.read_text(errors="replace")
        except OSError:
            return ""

    def stop(self) -> None:
        stop(self.proc)


def _server_running(name: str) -> bool:
    env = dict(os.environ, JACK_DEFAULT_SERVER=name)
    try:
        r = subprocess.run(["jack_wait", "-c"], env=env, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.stdout.strip() == "running"


# ------------------------------------------------------------------ JACK clients in this process
class Monitor:
    """A JACK client (no process callback) counting the server's xrun callbacks; port queries."""

    def __init__(self, server: str) -> None:
        import jack

        self.client = jack.Client("peers-monitor", servername=server, no_start_server=True)
        self.xruns = 0
        self.client.set_xrun_callback(self._xrun)
        self.client.activate()

    def _xrun(self, delayed_usecs: float) -> None:
        self.xruns += 1

    def cpu_load(self) -> float:
        return float(self.client.cpu_load())

    def find_output(self, exclude: tuple[str, ...] = ("system:", "peers-")) -> str | None:
        ports = self.client.get_ports(is_audio=True, is_output=True)
        names = sorted(p.name for p in ports if not p.name.startswith(exclude))
        return names[0] if names else None

    def ensure_playback(self, port: str) -> list[str]:
        """Connect the target to system:playback_1 (as to a device) if it is not; its connections."""
        try:
            conns = [p.name for p in self.client.get_all_connections(port)]
            if "system:playback_1" not in conns:
                self.client.connect(port, "system:playback_1")
            return [p.name for p in self.client.get_all_connections(port)]
        except Exception as exc:
            return [f"error: {exc}"]

    def close(self) -> None:
        try:
            self.client.deactivate()
        finally:
            self.client.close()


class Capture:
    """A JACK client recording one port into numpy while armed (stamped per sample and per cycle).

    One client stays connected for many trials: :meth:`reset` rewinds it (while disarmed).
    """

    def __init__(self, server: str, source: str, seconds: float) -> None:
        import jack

        self.client = jack.Client("peers-capture", servername=server, no_start_server=True)
        self.rate = int(self.client.samplerate)
        self.period = int(self.client.blocksize)
        cycles = int(seconds * self.rate) // self.period + 1
        self.port = self.client.inports.register("in_1")
        self.data = np.zeros(cycles * self.period, dtype=np.float32)
        # JACK frame time of every captured sample: a cycle the capture client misses (an
        # xrun) leaves a gap in ``data`` but not in the mapping from send frames to samples.
        self.frame_of = np.zeros(self.data.shape[0], dtype=np.int64)
        # CLOCK_MONOTONIC time (ns) of every captured sample: the cycle's actual start (the
        # callback's entry minus JACK's frames_since_cycle_start) plus the sample's offset.
        self.ns_of = np.zeros(self.data.shape[0], dtype=np.int64)
        # per captured cycle: its actual start (ns) and its first sample in ``data``
        self.cycle_ns = np.zeros(cycles, dtype=np.int64)
        self.cycle_first = np.zeros(cycles, dtype=np.int64)
        self._ramp = np.arange(8192, dtype=np.int64)
        self.frames = 0
        self.cycles = 0
        self.start_frame: int | None = None
        self.armed = False
        self.client.set_process_callback(self._process)
        self.client.activate()
        self.client.connect(source, self.port)

    def _process(self, frames: int) -> None:
        if not self.armed:
            return
        pos = self.frames
        n = min(frames, self.data.shape[0] - pos)
        if n <= 0 or self.cycles >= self.cycle_ns.shape[0]:
            return
        now = time.monotonic_ns()
        first = self.client.last_frame_time
        begin = now - int(self.client.frames_since_cycle_start * 1e9 / self.rate)
        if pos == 0:
            self.start_frame = first
        self.data[pos : pos + n] = self.port.get_array()[:n]
        self.frame_of[pos : pos + n] = first + self._ramp[:n]
        self.ns_of[pos : pos + n] = begin + self._ramp[:n] * 1_000_000_000 // self.rate
        self.cycle_ns[self.cycles] = begin
        self.cycle_first[self.cycles] = pos
        self.cycles += 1
        self.frames = pos + n

    def reset(self) -> None:
        """Rewind to empty (call while disarmed)."""
        self.frames, self.cycles, self.start_frame = 0, 0, None

    def frame_now(self) -> int:
        return int(self.client.frame_time)

    def close(self) -> None:
        try:
            self.client.deactivate()
        finally:
            self.client.close()

    def __enter__(self) -> Capture:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class JackAgent:
    """The :class:`Monitor` and :class:`Capture` of one JACK server, run in a child process.

    libjack (JACK2) serves one server per process, and the peers' servers run at the same time
    (their latency trials are interleaved), so each server's clients live in their own
    ``bench_peers.py _jack_agent`` child, driven by one JSON line per request on its stdin.
    Capture times are CLOCK_MONOTONIC, the clock of the sends in this process.
    """

    def __init__(self, jackd: JackServer, logdir: Path) -> None:
        cmd = [sys.executable, str(Path(__file__).resolve()), "_jack_agent", "--server", jackd.name]
        self.proc = spawn(
            cmd, env=jackd.env, log=logdir / f"agent-{jackd.name}.log", stdout=subprocess.PIPE, stdin=subprocess.PIPE
        )
        self.call("hello", timeout=30.0)

    def call(self, op: str, timeout: float = 10.0, **kw) -> dict:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write((json.dumps({"op": op, **kw}) + "\n").encode())
        self.proc.stdin.flush()
        deadline = time.monotonic() + timeout
        while True:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError(f"JACK agent exited ({self.proc.poll()}) during {op}")
            try:
                reply = json.loads(line)
            except ValueError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"JACK agent: no reply to {op}") from None
                continue  # something libjack printed
            if isinstance(reply, dict) and "error" in reply:
                raise RuntimeError(f"JACK agent ({op}): {reply['error']}")
            return reply

    @property
    def xruns(self) -> int:
        return int(self.call("xruns")["xruns"])

    def cpu_load(self) -> float:
        return float(self.call("cpu_load")["load"])

    def find_output(self) -> str | None:
        return self.call("find_output")["port"]

    def ensure_playback(self, port: str) -> list[str]:
        return self.call("ensure_playback", port=port)["connections"]

    def capture_open(self, source: str, seconds: float) -> None:
        self.call("capture_open", source=source, seconds=seconds)

    def arm(self) -> None:
        """Rewind the capture and record from now on."""
        self.call("arm")

    def levels(self) -> dict:
        """Stop recording; RMS and peak of what was recorded since :meth:`arm`."""
        return self.call("levels")

    def trial(self, sent_ns: int, gap: float) -> dict:
        """Stop recording; :func:`analyse_trial` of a send at ``sent_ns`` (CLOCK_MONOTONIC)."""
        return self.call("trial", sent_ns=sent_ns, gap=gap)

    def capture_close(self) -> None:
        self.call("capture_close")

    def close(self) -> None:
        try:
            self.call("close", timeout=5.0)
        except (RuntimeError, OSError, ValueError):
            pass
        stop(self.proc, timeout=5.0)


def jack_agent(argv: list[str]) -> int:
    """The child of :class:`JackAgent`: one JSON request per stdin line, one JSON reply per line."""
    p = argparse.ArgumentParser()
    p.add_argument("--server", required=True)
    a = p.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    mon = Monitor(a.server)
    cap: Capture | None = None
    out = sys.stdout
    for line in sys.stdin:
        req = json.loads(line)
        op = req["op"]
        reply: dict = {}
        try:
            if op == "find_output":
                reply = {"port": mon.find_output()}
            elif op == "ensure_playback":
                reply = {"connections": mon.ensure_playback(req["port"])}
            elif op == "cpu_load":
                reply = {"load": mon.cpu_load()}
            elif op == "xruns":
                reply = {"xruns": mon.xruns}
            elif op == "capture_open":
                cap = Capture(a.server, req["source"], req["seconds"])
            elif op == "clock":
                assert cap is not None
                n = cap.cycles
                reply = {
                    "cycle_ns": int(cap.cycle_ns[n - 1]) if n else None,
                    "period_ns": cap.period * 1e9 / cap.rate,
                }
            elif op == "arm":
                assert cap is not None
                cap.armed = False
                cap.reset()
                cap.armed = True
            elif op in ("levels", "trial"):
                assert cap is not None
                cap.armed = False
                time.sleep(0.005)  # a callback that saw ``armed`` just before finishes its copy
                if op == "levels":
                    x = cap.data[: cap.frames].astype(np.float64)
                    reply = {
                        "frames": int(x.size),
                        "rms": float(np.sqrt(np.mean(x**2))) if x.size else 0.0,
                        "max_abs": float(np.max(np.abs(x))) if x.size else None,
                    }
                else:
                    # jack_frame_time() at the send: its value now, less the frames since on CLOCK_MONOTONIC
                    frame_now, ns_now = cap.frame_now(), time.monotonic_ns()
                    sent_frame = frame_now - round((ns_now - req["sent_ns"]) * cap.rate / 1e9)
                    reply = analyse_trial(cap, sent_frame, int(req["sent_ns"]), float(req["gap"]))
            elif op == "capture_close":
                if cap is not None:
                    cap.close()
                cap = None
            elif op == "close":
                out.write("{}\n")
                out.flush()
                break
        except Exception as exc:
            reply = {"error": f"{type(exc).__name__}: {exc}"}
        out.write(json.dumps(reply) + "\n")
        out.flush()
    if cap is not None:
        cap.close()
    mon.close()
    return 0


# ------------------------------------------------------------------ the targets
class Target:
    name = ""
    client_name = ""

    def __init__(self, jackd: JackServer, tmp: Path, gains: list[float], args) -> None:
        self.jackd, self.tmp, self.gains, self.args = jackd, tmp, gains, args
        self.port = free_udp_port()
        self.proc: subprocess.Popen | None = None
        self.osc: OscClient | None = None
        self.log = tmp / f"{self.name}.log"
        self.version = ""
        self.settings: dict = {}

    def start(self) -> None: ...

    def set_loud(self, loud: bool) -> None: ...

    def flood_messages(self) -> list[bytes]: ...

    def status(self) -> dict | None:
        return None

    def flood_changes_level(self) -> bool:
        return False

    def stop(self) -> None:
        if self.osc:
            self.osc.close()
        stop(self.proc)

    def _wait_ready(self, probe, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            if self.proc is not None and self.proc.poll() is not None:
                raise RuntimeError(f"{self.name} exited ({self.proc.returncode}); log:\n{self.log_tail()}")
            try:
                probe()
                return
            except (TimeoutError, OSError):
                if time.monotonic() > deadline:
                    raise RuntimeError(
                        f"{self.name} not ready after {timeout:.0f} s; log:\n{self.log_tail()}"
                    ) from None

    def log_tail(self, n: int = 30) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""


class ScsynthTarget(Target):
    name = "scsynth"

    def start(self) -> None:
        env = dict(self.jackd.env, SC_JACK_DEFAULT_OUTPUTS="", SC_JACK_DEFAULT_INPUTS="")
        self.client_name = "scsynth-peer"
        cmd = [
            "scsynth",
            "-u",
            str(self.port),
            "-i",
            "0",
            "-o",
            "1",
            "-H",
            f"{self.jackd.name}:{self.client_name}",
            "-z",
            "64",
            "-R",
            "0",
            "-l",
            "1",
            "-D",
            "0",
        ]
        self.settings = {
            "command": " ".join(cmd),
            "control_block": 64,
            "filter": f"BPF (rq {RQ:.4f})",
            "synthdef": "WhiteNoise -> 30 x BPF * g_k (MulAdd chain) * amp -> Out (built in Python, v2)",
        }
        self.proc = spawn(cmd, env=env, log=self.log)
        self.osc = OscClient(self.port)
        self._wait_ready(lambda: self.osc.request(osc_message("/status"), "/status.reply", 0.3), 30)
        self.version = subprocess.run(["scsynth", "-v"], capture_output=True, text=True, timeout=10).stdout.strip()
        self.osc.request(osc_message("/d_recv", peer_synthdef()), "/done", 5.0)
        self.osc.send(osc_message("/s_new", SC_DEF_NAME, SC_NODE, 0, 0, "amp", 0.0))
        # by index: a *name* in /n_setn addresses only that named control's own channels (1 here)
        self.osc.send(osc_message("/n_setn", SC_NODE, 1, N_BANDS, *[float(g) for g in self.gains]))
        self.osc.request(osc_message("/sync", 1), "/synced", 5.0)

    def stop(self) -> None:
        super().stop()
        # scsynth leaves its shared-memory interface (8 MB) behind in /dev/shm, named by port
        try:
            Path(f"/dev/shm/SuperColliderServer_{self.port}").unlink()
        except OSError:
            pass

    def set_loud(self, loud: bool) -> None:
        self.osc.send(osc_message("/n_set", SC_NODE, "amp", 1.0 if loud else 0.0))

    def flood_messages(self) -> list[bytes]:
        return [
            osc_message("/n_set", SC_NODE, f"g{n % N_BANDS}", self.gains[n % N_BANDS] * (0.5 if n % 2 else 1.0))
            for n in range(2 * N_BANDS)
        ]


class PyoTarget(Target):
    name = "pyo"

    def start(self) -> None:
        self.client_name = "pyo-peer"
        cmd = [
            sys.executable,
            str(Path(__file__).resolve()),
            "_pyo_child",
            "--port",
            str(self.port),
            "--jackname",
            self.client_name,
            "--rate",
            str(self.jackd.rate),
            "--period",
            str(self.jackd.period),
        ]
        self.settings = {
            "server": f"Server(sr={self.jackd.rate}, nchnls=1, buffersize={self.jackd.period}, duplex=0, audio='jack')",
            "filter": "ButBP (q %.3f)" % (1 / RQ),
            "osc": "OscReceive (interpolation off), polled in pyo's audio callback",
        }
        self.proc = spawn(cmd, env=self.jackd.env, log=self.log)
        deadline = time.monotonic() + 60
        while "PEER-READY" not in self.log.read_text(errors="replace"):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"pyo child did not start; log:\n{self.log_tail()}")
            time.sleep(0.1)
        m = re.search(r"PEER-READY (\S+)", self.log.read_text(errors="replace"))
        self.version = f"pyo {m.group(1)}" if m else "pyo"
        self.osc = OscClient(self.port)
        for k, g in enumerate(self.gains):
            self.osc.send(osc_message(PYO_GAIN.format(k), float(g)))
        self.osc.send(osc_message(PYO_AMP, 0.0))

    def set_loud(self, loud: bool) -> None:
        self.osc.send(osc_message(PYO_AMP, 1.0 if loud else 0.0))

    def flood_messages(self) -> list[bytes]:
        return [
            osc_message(PYO_GAIN.format(n % N_BANDS), self.gains[n % N_BANDS] * (0.5 if n % 2 else 1.0))
            for n in range(2 * N_BANDS)
        ]


class VibsynthTarget(Target):
    name = "vibsynth"
    #: Lines added to the ``osc:`` section of its config (a variant's settings).
    osc_extra = ""

    def source(self) -> tuple[Path, str]:
        """The folder vibsynth runs from, and its description."""
        return self.args.vibsynth_src_dir or ROOT, self.args.vibsynth_source

    def start(self) -> None:
        src, label = self.source()
        exe = ROOT / ".venv" / "bin" / "vibsynth"
        # the working tree through the venv's console script, or a snapshot (--vibsynth-rev)
        # with ``python -m vibsynth`` run from inside it (so that it is the one imported)
        base = [str(exe)] if exe.exists() and src == ROOT else [sys.executable, "-m", "vibsynth"]
        config = self.tmp / f"{self.name}.yaml"
        config.write_text(
            "version: 1\n"
            f"audio:\n  host_api: JACK\n  rate: {self.jackd.rate}\n  block_size: {self.jackd.period}\n  channels: 1\n"
            f"osc:\n  port: {self.port}\n{self.osc_extra}"
            "knobs:\n  glide_ms: 0\n",
            encoding="utf-8",
        )
        cmd = base + [
            "serve",
            "--config",
            str(config),
            "--output",
            "sounddevice",
            "--no-midi",
            "--osc-port",
            str(self.port),
        ]
        env = dict(self.jackd.env, VIBSYNTH_HOST_API="JACK", PYTHONPATH=str(src))
        self.settings = {
            "command": " ".join(["vibsynth"] + cmd[len(base) :]),
            "config": config.read_text(),
            "flood": f"/vibsynth/{self.args.vibsynth_flood}",
            "source": label,
        }
        self.proc = spawn(cmd, env=env, log=self.log, cwd=src)
        self.osc = OscClient(self.port)
        self._wait_ready(lambda: self.osc.request(osc_message("/vibsynth/ping", 1), "/vibsynth/pong", 0.3), 180)
        st = self.status()
        self.version = f"vibsynth {st.get('version', '?')} ({label})"
        self.osc.send(osc_message("/vibsynth/glide", 0.0))
        self.osc.send(osc_message("/vibsynth/texture", 0.0, 0.0))
        self.osc.request(osc_message("/vibsynth/sync", 1), "/vibsynth/synced", 5.0)

    def set_loud(self, loud: bool) -> None:
        self.osc.send(osc_message("/vibsynth/intensity", 0.8 if loud else 0.0))

    def status(self) -> dict:
        for _ in range(3):
            try:
                args = self.osc.request(osc_message("/vibsynth/status"), "/vibsynth/status.reply", 2.0)
                return dict(zip(args[::2], args[1::2]))
            except TimeoutError:
                continue
        return {}

    def flood_changes_level(self) -> bool:
        return self.args.vibsynth_flood != "balance"

    def flood_messages(self) -> list[bytes]:
        kind = self.args.vibsynth_flood
        vals = [0.5 if n % 2 else -0.5 for n in range(2 * N_BANDS)]
        if kind == "balance":
            return [osc_message("/vibsynth/balance", v) for v in vals]
        if kind == "intensity":
            return [osc_message("/vibsynth/intensity", 0.8 if n % 2 else 0.7) for n in range(2 * N_BANDS)]
        return [osc_message("/vibsynth/texture", 0.8 if n % 2 else 0.7, v) for n, v in enumerate(vals)]


class VibsynthRefTarget(VibsynthTarget):
    """A second vibsynth from ``--vibsynth-ref DIR`` (built in place), interleaved with the first:
    a before/after comparison under the very same load."""

    name = "vibsynth-ref"

    def source(self) -> tuple[Path, str]:
        return self.args.vibsynth_ref.resolve(), f"source folder {self.args.vibsynth_ref.resolve()}"


class VibsynthNoFifoTarget(VibsynthTarget):
    """vibsynth with its OSC receive loop normally scheduled (``osc.receive_priority: 0``), not SCHED_FIFO."""

    name = "vibsynth-nofifo"
    osc_extra = "  receive_priority: 0\n"


TARGETS = {
    "scsynth": ScsynthTarget,
    "pyo": PyoTarget,
    "vibsynth": VibsynthTarget,
    "vibsynth-ref": VibsynthRefTarget,
    "vibsynth-nofifo": VibsynthNoFifoTarget,
}
REFERENCE = "vibsynth-ref"


def vibsynth_snapshot(rev: str, tmp: Path) -> tuple[Path, str]:
    """``git archive rev`` into tmp, with the C core built in place: (folder, description)."""
    commit = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{rev}^{{commit}}"],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    ).stdout.strip()
    dest = tmp / f"vibsynth-{commit[:10]}"
    dest.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], capture_output=True, timeout=120, check=True)
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive.stdout, timeout=120, check=True)
    log = tmp / "vibsynth-build.log"
    with open(log, "wb") as fh:
        r = subprocess.run(
            [sys.executable, "setup.py", "-q", "build_ext", "--inplace"],
            cwd=dest,
            stdout=fh,
            stderr=subprocess.STDOUT,
            timeout=600,
        )
    if r.returncode != 0:
        raise RuntimeError(f"building vibsynth at {commit[:10]} failed:\n{log.read_text(errors='replace')[-2000:]}")
    subject = subprocess.run(
        ["git", "-C", str(ROOT), "log", "-1", "--format=%h %s", commit], capture_output=True, text=True, timeout=30
    ).stdout.strip()
    return dest, f"git {rev} = {subject[:90]}"


def peer_missing(peer: str) -> str | None:
    """Why a peer cannot run here (None: it can)."""
    if peer == "scsynth" and shutil.which("scsynth") is None:
        return "scsynth not found (Debian: apt-get install --no-install-recommends supercollider-server)"
    if peer == "pyo" and importlib.util.find_spec("pyo") is None:
        return f"pyo is not installed in {sys.executable} (pip install pyo)"
    return None


# ------------------------------------------------------------------ measurements
CLK_TCK = os.sysconf("SC_CLK_TCK")


def proc_cpu_seconds(pid: int | None) -> float | None:
    if pid is None:
        return None
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime (fields 14, 15)
    except (OSError, IndexError, ValueError):
        return None


def system_cpu() -> tuple[int, int]:
    with open("/proc/stat") as fh:
        vals = [int(v) for v in fh.readline().split()[1:]]
    idle = vals[3] + (vals[4] if len(vals) > 4 else 0)
    return sum(vals) - idle, sum(vals)


def _pct(a: float | None, b: float | None, dt: float) -> float | None:
    return None if a is None or b is None or dt <= 0 else 100.0 * (b - a) / dt


class Snapshot:
    def __init__(
        self, target: Target, jackd: JackServer, mon: Monitor | JackAgent, sender: subprocess.Popen | None
    ) -> None:
        self.t = time.monotonic()
        self.cpu = proc_cpu_seconds(target.proc.pid if target.proc else None)
        self.jackd_cpu = proc_cpu_seconds(jackd.proc.pid if jackd.proc else None)
        self.sender_cpu = proc_cpu_seconds(sender.pid) if sender else None
        self.sys = system_cpu()
        self.xruns = mon.xruns
        self.log_len = len(jackd.log_text())
        st = target.status()
        self.underflows = st.get("underflows") if st else None
        self.packets = st.get("packets") if st else None


def jackd_events(text: str, client: str) -> dict:
    lines = text.splitlines()
    target = sum(1 for ln in lines if f"client = {client} was not finished" in ln)
    return {
        "target_late_cycles": target,
        "other_clients_late": sum(1 for ln in lines if "was not finished" in ln) - target,
        "driver_late_wakeups": sum(1 for ln in lines if "JackTimedDriver::Process XRun" in ln),
        "process_errors": sum(1 for ln in lines if "Process error" in ln),
    }


def window(a: Snapshot, b: Snapshot, jackd: JackServer, client: str) -> dict:
    dt = b.t - a.t
    busy = (b.sys[0] - a.sys[0]) / max(1, b.sys[1] - a.sys[1])
    out = {
        "seconds": dt,
        "cpu_pct": _pct(a.cpu, b.cpu, dt),
        "jackd_cpu_pct": _pct(a.jackd_cpu, b.jackd_cpu, dt),
        "sender_cpu_pct": _pct(a.sender_cpu, b.sender_cpu, dt),
        "machine_busy_pct_of_all_cores": 100.0 * busy,
        "xrun_callbacks": b.xruns - a.xruns,
    }
    out.update(jackd_events(jackd.log_text()[a.log_len : b.log_len], client))
    if a.underflows is not None and b.underflows is not None:
        out["status_underflows"] = int(b.underflows - a.underflows)
    if a.packets is not None and b.packets is not None:
        out["status_packets"] = int(b.packets - a.packets)
    return out


def baseline(jackd: JackServer, mon: Monitor | JackAgent, seconds: float) -> dict:
    """The JACK server with no target: how often the dummy driver itself wakes late here."""
    t0, cpu0, sys0, x0, n0 = (
        time.monotonic(),
        proc_cpu_seconds(jackd.proc.pid),
        system_cpu(),
        mon.xruns,
        len(jackd.log_text()),
    )
    loads = []
    end = t0 + seconds
    while time.monotonic() < end:
        time.sleep(min(0.25, max(0.0, end - time.monotonic())))
        loads.append(mon.cpu_load())
    dt = time.monotonic() - t0
    sys1 = system_cpu()
    out = {
        "seconds": dt,
        "jackd_cpu_pct": _pct(cpu0, proc_cpu_seconds(jackd.proc.pid), dt),
        "machine_busy_pct_of_all_cores": 100.0 * (sys1[0] - sys0[0]) / max(1, sys1[1] - sys0[1]),
        "xrun_callbacks": mon.xruns - x0,
        "dsp_load_mean_pct": float(np.mean(loads)) if loads else None,
    }
    out.update(jackd_events(jackd.log_text()[n0:], "(none)"))
    return out


def one_trial(target: Target, agent: JackAgent, gap: float, before_cycle: float | None = None) -> dict:
    """One latency trial: silence, ``gap`` s, note the time, loud, ``gap`` s; then its analysis.

    ``before_cycle`` (a fraction of the period, 0..1): send that long before a start of the
    target's cycle, predicted from the last cycle start the capture saw (None: whenever the gap
    ends). The interleaved trials give every peer of a round the same fraction (common random
    numbers) and the rounds' fractions cover the period evenly (stratified), so the wait for the
    next cycle, the same for every engine, no longer hides their difference. The wait actually
    met is measured (``wait_s``), not assumed. Returns :func:`analyse_trial`'s dict (``rejected``
    names the reason when it is not usable).
    """
    agent.arm()
    target.set_loud(False)
    time.sleep(gap)
    if before_cycle is not None:
        clock = agent.call("clock")
        if clock["cycle_ns"] is not None:
            start, period = int(clock["cycle_ns"]), float(clock["period_ns"])
            lead = before_cycle * period
            k = math.ceil((time.monotonic_ns() + 1_500_000 + lead - start) / period)
            when = start + k * period - lead
            time.sleep(max(0.0, (when - time.monotonic_ns()) / 1e9 - 0.0004))
            while time.monotonic_ns() < when:  # the last 0.4 ms spinning: sleep() wakes tens of us late
                pass
    sent_ns = time.monotonic_ns()
    target.set_loud(True)
    time.sleep(gap)
    return agent.trial(sent_ns, gap)


def analyse_trial(cap: Capture, sent_frame: int, sent_ns: int, gap: float) -> dict:
    """Send -> first changed output sample of one trial, on two clocks, and where it fell.

    ``wall_s`` (the default clock): CLOCK_MONOTONIC just before the send vs the actual start of
    the JACK cycle holding the first non-silent sample, plus the sample's offset in the cycle.
    ``frame_s``: as benchmarks/bench_osc.py, ``jack_frame_time()`` just before the send vs the
    frame of that sample. ``jack_frame_time()`` is JACK's DLL estimate of the current frame;
    after the dummy driver wakes late it can be off by tens of ms for seconds (seen on the
    2-core VM), so trials are located and timed on the wall clock.

    Where the time goes: ``wait_s`` is the time from the send to the start of the next cycle
    (what any engine that applies a message at the next cycle start must wait), and
    ``cycles_after`` says which cycle took the message: 0 that next one, -1 the cycle already
    running at the send (its callback started after the send, late in its cycle), 1 or more a
    cycle missed (the message reached the audio callback too late for the next one).
    ``excess_s`` = ``wall_s`` - ``wait_s``.
    """
    rate, period, frames = cap.rate, cap.period, cap.frames
    data, frame_of, ns_of = cap.data[:frames], cap.frame_of[:frames], cap.ns_of[:frames]
    cycle_ns, cycle_first = cap.cycle_ns[: cap.cycles], cap.cycle_first[: cap.cycles]
    out: dict = {"rejected": None, "capture_gaps": int(np.count_nonzero(np.diff(frame_of) != 1)) if frames > 1 else 0}
    span = int(gap * rate)
    # A target cycle that runs late (VM jitter) still takes messages sent after its nominal
    # start, so the onset can come before the send on either clock by up to about a period:
    # look from ``lead`` frames before the send (silent there: the level was set to 0 ``gap``
    # earlier) and keep such zero or negative latencies as measured.
    lead_ns = 2 * period * 1_000_000_000 // rate
    after = ns_of >= sent_ns  # (not always monotonic: cycles catch up after a late one)
    first = int(np.argmax(after)) if after.any() else frames
    before = ns_of >= sent_ns - lead_ns
    start = int(np.argmax(before)) if before.any() else frames
    if start < 64 or first + span > frames:
        out["rejected"] = "outside capture"
        return out
    if np.any(np.abs(data[start - 64 : start]) > SILENT_THRESHOLD):
        out["rejected"] = "not silent before"
        return out
    onset = np.flatnonzero(np.abs(data[start : first + span]) > SILENT_THRESHOLD)
    if not onset.size:
        out["rejected"] = "no onset"
        return out
    i = start + int(onset[0])
    out["frame_s"] = int(frame_of[i] - sent_frame) / rate
    out["wall_s"] = int(ns_of[i] - sent_ns) / 1e9
    following = np.flatnonzero(cycle_ns >= sent_ns)
    if following.size:
        onset_cycle = int(np.searchsorted(cycle_first, i, side="right")) - 1
        next_ns = int(cycle_ns[following[0]])
        period_ns = period * 1e9 / rate
        out["wait_s"] = (next_ns - sent_ns) / 1e9
        out["excess_s"] = out["wall_s"] - out["wait_s"]
        out["cycles_after"] = int(round((int(cycle_ns[onset_cycle]) - next_ns) / period_ns))
        out["offset_in_cycle"] = int(i - cycle_first[onset_cycle])
    return out


def latency_trials(target: Target, agent: JackAgent, source: str, trials: int, gap: float) -> list[dict]:
    """``trials`` trials in a row on one target (the flood phase): their :func:`one_trial` dicts."""
    agent.capture_open(source, 2 * gap + 0.5)
    try:
        target.set_loud(False)
        time.sleep(0.2)
        return [one_trial(target, agent, gap) for _ in range(trials)]
    finally:
        agent.capture_close()


TRIAL_COLUMNS = ("round", "position", "before_cycle", "wall_s", "frame_s", "wait_s", "cycles_after", "rejected")


def trial_log(trials: list[dict]) -> dict:
    """Every trial, by column (times rounded to 1 us): what the JSON keeps of the idle trials."""

    def value(t: dict, key: str):
        v = t.get(key)
        return round(v, 4 if key == "before_cycle" else 6) if isinstance(v, float) else v

    return {key: [value(t, key) for t in trials] for key in TRIAL_COLUMNS}


def _ms(values) -> list[float]:
    return [1e3 * v for v in values]


def _lat_summary(values_s: list[float], keep_all: bool = True) -> dict:
    """Median (with its 95 % order-statistic interval), p95, mean, range (and, ``keep_all``, every
    value) of latencies in seconds."""
    if not values_s:
        return {"median_ms": None, "p95_ms": None, "min_ms": None, "max_ms": None, "not_positive": 0, "all_ms": []}
    ms = _ms(values_s)
    med, lo, hi = median_ci(ms)
    return {
        "median_ms": med,
        "median_ci95_ms": [lo, hi],
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(np.mean(ms)),
        "min_ms": min(ms),
        "max_ms": max(ms),
        "not_positive": sum(1 for x in values_s if x <= 0),
        **({"all_ms": [round(x, 3) for x in ms]} if keep_all else {}),
    }


def summarise_trials(results: list[dict], clock: str) -> dict:
    """The latency block of a phase from its trials (accepted and rejected)."""
    ok = [t for t in results if not t["rejected"]]
    rejected: dict[str, int] = {}
    for t in results:
        if t["rejected"]:
            rejected[t["rejected"]] = rejected.get(t["rejected"], 0) + 1
    placed = [t for t in ok if "cycles_after" in t]
    hist: dict[str, int] = {}
    for t in placed:
        key = str(max(-1, min(2, t["cycles_after"])))
        hist[key] = hist.get(key, 0) + 1
    excess = _ms(t["excess_s"] for t in placed)
    return {
        "trials": len(ok),
        "clock": clock,
        **_lat_summary([t[f"{clock}_s"] for t in ok]),
        "frame_clock": _lat_summary([t["frame_s"] for t in ok], keep_all=False),
        "wall_clock": _lat_summary([t["wall_s"] for t in ok], keep_all=False),
        "wait_to_next_cycle": _lat_summary([t["wait_s"] for t in placed], keep_all=False),
        "excess_mean_ms": float(np.mean(excess)) if excess else None,
        "cycle_taken": {
            "meaning": "-1 the cycle running at the send, 0 the next, 1 one missed, 2 two or more",
            **{k: hist.get(k, 0) for k in ("-1", "0", "1", "2")},
        },
        "rejected": rejected,
        "capture_gaps": sum(t["capture_gaps"] for t in results),
    }


def level_check(target: Target, agent: JackAgent, source: str) -> dict:
    """Loud then silent for 0.4 s each: the synth really runs and silence is exact."""
    agent.capture_open(source, 1.0)
    try:
        target.set_loud(True)
        time.sleep(0.2)
        agent.arm()
        time.sleep(0.4)
        loud = agent.levels()
        target.set_loud(False)
        time.sleep(0.2)
        agent.arm()
        time.sleep(0.4)
        quiet = agent.levels()
    finally:
        agent.capture_close()
    target.set_loud(True)
    rms = loud["rms"]
    return {
        "loud_rms": rms,
        "loud_dbfs": 20 * math.log10(rms) if rms > 0 else None,
        "silent_max_abs": quiet["max_abs"],
    }


def start_sender(target: Target, rate: int, max_seconds: float, tmp: Path) -> subprocess.Popen:
    msgs = target.flood_messages()
    path = tmp / f"flood-{target.name}.bin"
    path.write_bytes(b"".join(struct.pack(">I", len(m)) + m for m in msgs))
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "_flood",
        "--port",
        str(target.port),
        "--rate",
        str(rate),
        "--max-seconds",
        str(max_seconds),
        "--messages",
        str(path),
    ]
    return spawn(cmd, env=dict(os.environ), log=tmp / f"flood-{target.name}.log", stdout=subprocess.PIPE)


def stop_sender(proc: subprocess.Popen) -> dict:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate(timeout=5)
    if proc in _CHILDREN:
        _CHILDREN.remove(proc)
    try:
        return json.loads(out.decode().strip().splitlines()[-1])
    except (ValueError, IndexError):
        return {"error": f"sender output: {out[-200:]!r}"}


def measure_window(run: PeerRun, seconds: float, sender: subprocess.Popen | None) -> dict:
    """CPU, DSP load and xruns of one target over ``seconds`` of loud streaming."""
    target, jackd, mon = run.target, run.jackd, run.mon
    target.set_loud(True)
    time.sleep(0.2)
    a = Snapshot(target, jackd, mon, sender)
    loads = []
    end = a.t + seconds
    while time.monotonic() < end:
        time.sleep(min(0.25, max(0.0, end - time.monotonic())))
        loads.append(mon.cpu_load())
    b = Snapshot(target, jackd, mon, sender)
    out = window(a, b, jackd, target.client_name)
    out["dsp_load_mean_pct"] = float(np.mean(loads)) if loads else None
    out["dsp_load_max_pct"] = float(np.max(loads)) if loads else None
    out["loadavg"] = os.getloadavg()
    return out


def flood_phase(run: PeerRun, args, tmp: Path) -> dict:
    """The flood phase of one target: the window, then ``--trials`` trials in a row, under the flood."""
    target, jackd, mon = run.target, run.jackd, run.mon
    sender = start_sender(target, args.rate, args.seconds + args.trials * 2 * args.gap + 30, tmp)
    time.sleep(0.5)
    if sender.poll() is not None:
        raise RuntimeError(f"flood sender exited: {stop_sender(sender)}")
    result: dict = {"phase": "flood"}
    a = Snapshot(target, jackd, mon, sender)
    result["window"] = measure_window(run, args.seconds, sender)
    b = Snapshot(target, jackd, mon, sender)
    if target.flood_changes_level():
        result["latency"] = {
            **summarise_trials([], args.latency_clock),
            "skipped": f"the flood ({args.vibsynth_flood}) sets the level",
        }
    else:
        trials = latency_trials(target, mon, run.source, args.trials, args.gap) if args.trials > 0 else []
        result["latency"] = summarise_trials(trials, args.latency_clock)
    c = Snapshot(target, jackd, mon, sender)
    result["latency_window"] = window(b, c, jackd, target.client_name)
    result["phase_total"] = window(a, c, jackd, target.client_name)
    result["sender"] = stop_sender(sender)
    target.set_loud(True)
    return result


class PeerRun:
    """One peer for the whole run: its private JACK server, monitor, target and results entry."""

    def __init__(self, peer: str, args, tmp: Path, gains: list[float]) -> None:
        self.peer, self.args = peer, args
        self.entry: dict = {"peer": peer, "when": time.strftime("%Y-%m-%d %H:%M:%S"), "loadavg_before": os.getloadavg()}
        self.jackd = JackServer(f"bench-peers-{peer}", args.jack_rate, args.jack_period, tmp)
        self.target: Target = TARGETS[peer](self.jackd, tmp, gains, args)
        self.mon: JackAgent = None  # type: ignore[assignment]
        self.tmp = tmp
        self.source = ""
        self.stopped = False

    @property
    def ok(self) -> bool:
        return "error" not in self.entry

    def fail(self, exc: BaseException) -> None:
        self.entry["error"] = f"{type(exc).__name__}: {exc}"
        print(f"  {self.peer}: FAILED: {self.entry['error']}", file=sys.stderr, flush=True)
        self.stop()

    def start(self) -> None:
        """JACK server, its baseline, the target, its output port, the level check (raises on failure)."""
        args, jackd, target, peer = self.args, self.jackd, self.target, self.peer
        jackd.start()
        self.entry["jack"] = {
            "server": jackd.name,
            "driver": "dummy",
            "rate": jackd.rate,
            "period": jackd.period,
            "realtime": jackd.realtime,
            "command": f"jackd -n {jackd.name} {'-R ' if jackd.realtime else ''}-d dummy -r {jackd.rate} "
            f"-p {jackd.period}",
        }
        self.mon = JackAgent(jackd, self.tmp)
        if args.baseline > 0:
            print(f"  {peer}: baseline ({args.baseline:g} s of the JACK server alone)", flush=True)
            self.entry["baseline"] = baseline(jackd, self.mon, args.baseline)
        t0 = time.monotonic()
        target.start()
        self.entry["startup_s"] = time.monotonic() - t0
        deadline = time.monotonic() + 30
        source = self.mon.find_output()
        while source is None and time.monotonic() < deadline:
            time.sleep(0.1)
            source = self.mon.find_output()
        if source is None:
            raise RuntimeError(f"{peer} registered no JACK output port; log:\n{target.log_tail()}")
        self.source = source
        target.client_name = source.split(":", 1)[0]
        self.entry.update(
            version=target.version,
            settings=target.settings,
            jack_port=source,
            connections=self.mon.ensure_playback(source),
            flood_rate=args.rate,
        )
        time.sleep(args.warmup)
        self.entry["level_check"] = level_check(target, self.mon, source)
        if self.entry["level_check"]["loud_rms"] <= 0:
            raise RuntimeError(f"{peer} output is silent at the loud setting; log:\n{target.log_tail()}")
        self.entry["phases"] = {}

    def stop(self) -> None:
        if self.stopped:
            return
        self.stopped = True
        if self.peer == "vibsynth" and self.ok and self.target.proc is not None and self.target.proc.poll() is None:
            self.entry["status_end"] = self.target.status()
        try:
            self.target.stop()
        finally:
            if self.mon is not None:
                try:
                    self.mon.close()
                except Exception:
                    pass
            self.jackd.stop()
        self.entry["jackd_log_totals"] = jackd_events(self.jackd.log_text(), self.target.client_name or self.peer)


def interleaved_idle_latency(runs: list[PeerRun], args) -> dict:
    """The idle latency trials of every running peer, interleaved: ``--idle-trials`` rounds, one
    trial of each peer per round in a fresh random order (seeded by ``--seed``), so machine load
    hits all peers alike. Per peer its trials (with ``round``), plus the stage's load."""
    rng = np.random.default_rng(args.seed)
    opened: list[PeerRun] = []
    trials: dict[str, list[dict]] = {run.peer: [] for run in runs}
    snaps = {}
    try:
        for run in runs:
            run.mon.capture_open(run.source, 2 * args.gap + 0.5)
            opened.append(run)
            run.target.set_loud(False)
        time.sleep(0.2)
        for run in runs:
            snaps[run.peer] = Snapshot(run.target, run.jackd, run.mon, None)
        t0, sys0, load0 = time.monotonic(), system_cpu(), os.getloadavg()
        busy_per_round = []
        # stratified send phases, one per round, shared by the round's peers (see one_trial)
        strata = rng.permutation(args.idle_trials)
        for r in range(args.idle_trials):
            rs0 = system_cpu()
            order = rng.permutation(len(runs))
            before = (strata[r] + rng.random()) / args.idle_trials if args.phase == "stratified" else None
            for position, k in enumerate(order):
                run = runs[int(k)]
                t = one_trial(run.target, run.mon, args.gap, before)
                t.update(round=r, position=position, before_cycle=before)
                trials[run.peer].append(t)
            rs1 = system_cpu()
            busy_per_round.append(100.0 * (rs1[0] - rs0[0]) / max(1, rs1[1] - rs0[1]))
            if (r + 1) % 100 == 0:
                print(f"    round {r + 1}/{args.idle_trials}, load {os.getloadavg()[0]:.2f}", flush=True)
        sys1 = system_cpu()
        stage = {
            "rounds": args.idle_trials,
            "seconds": time.monotonic() - t0,
            "gap_s": args.gap,
            "seed": args.seed,
            "phase": args.phase,
            "loadavg_before": load0,
            "loadavg_after": os.getloadavg(),
            "machine_busy_pct_of_all_cores": 100.0 * (sys1[0] - sys0[0]) / max(1, sys1[1] - sys0[1]),
            "machine_busy_pct_per_round_p10_p50_p90": [float(v) for v in np.percentile(busy_per_round, [10, 50, 90])],
        }
        for run in runs:
            end = Snapshot(run.target, run.jackd, run.mon, None)
            stage.setdefault("windows", {})[run.peer] = window(snaps[run.peer], end, run.jackd, run.target.client_name)
    finally:
        for run in opened:
            try:
                run.mon.capture_close()
            except Exception:
                pass
        for run in runs:
            try:
                run.target.set_loud(True)
            except Exception:
                pass
    return {"stage": stage, "trials": trials}


def compare_idle(trials: dict[str, list[dict]], rounds: int, clock: str) -> dict:
    """vibsynth's idle median against the better peer's (lower median), with paired-bootstrap intervals."""
    ok = {p: [t for t in ts if not t["rejected"]] for p, ts in trials.items()}
    if "vibsynth" not in ok or len(ok) < 2 or not all(ok.values()):
        return {}
    names, m = round_matrix(ok, f"{clock}_s", rounds)
    m = 1e3 * m
    v = names.index("vibsynth")
    others = [k for k, n in enumerate(names) if n not in ("vibsynth", REFERENCE)]
    if not others:
        return {}
    ref = names.index(REFERENCE) if REFERENCE in names else None

    def med(x: np.ndarray) -> np.ndarray:
        return np.nanmedian(x, axis=1)  # (batch, systems)

    def ratio_best(x: np.ndarray) -> np.ndarray:
        meds = med(x)
        return meds[:, v] / np.min(meds[:, others], axis=1)

    def diff_best(x: np.ndarray) -> np.ndarray:
        meds = med(x)
        return meds[:, v] - np.min(meds[:, others], axis=1)

    medians = np.nanmedian(m, axis=0)
    best = names[others[int(np.argmin(medians[others]))]]
    out: dict = {
        "clock": clock,
        "better_peer": best,
        "ratio_to_better_peer": list(paired_bootstrap(m, ratio_best)),
        "difference_to_better_peer_ms": list(paired_bootstrap(m, diff_best)),
        "per_peer": {},
        "interval": "95 %, bootstrap of whole rounds (4000 resamples, seed 0); the better peer is re-chosen "
        "in each resample",
    }
    placed = {p: [t for t in ts if "excess_s" in t] for p, ts in ok.items()}
    if all(placed.values()):
        _, e = round_matrix(placed, "excess_s", rounds)
        e = 1e3 * e

        def excess_diff(x: np.ndarray, k: int) -> np.ndarray:
            means = np.nanmean(x, axis=1)
            return means[:, v] - means[:, k]

        out["excess_mean_ms"] = {
            names[k]: list(paired_bootstrap(e, lambda x, k=k: np.nanmean(x, axis=1)[:, k])) for k in range(len(names))
        }
        out["excess_difference_ms"] = {
            names[k]: list(paired_bootstrap(e, lambda x, k=k: excess_diff(x, k)))
            for k in others + ([ref] if ref is not None else [])
        }
    for k in others + ([ref] if ref is not None else []):
        out["per_peer"][names[k]] = {
            "ratio": list(paired_bootstrap(m, lambda x, k=k: med(x)[:, v] / med(x)[:, k])),
            "difference_ms": list(paired_bootstrap(m, lambda x, k=k: med(x)[:, v] - med(x)[:, k])),
        }
    return out


# ------------------------------------------------------------------ machine info, table
def _git_describe() -> str:
    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(ROOT), "status", "--porcelain", "--", "vibsynth", "setup.py"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return f" (git {head}{', uncommitted changes in vibsynth/' if dirty else ''})"
    except Exception:
        return ""


def machine_info() -> dict:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    def first_line(cmd: list[str]) -> str:
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=10)
            return (r.stdout or r.stderr).strip().splitlines()[0]
        except Exception:
            return ""

    versions = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "jackd": first_line(["jackd", "--version"]),
        "scsynth": first_line(["scsynth", "-v"]),
    }
    try:
        import jack

        versions["JACK-Client"] = jack.__version__
    except Exception:
        pass
    try:
        from importlib.metadata import version

        versions["pyo"] = version("pyo")
    except Exception:
        pass
    try:
        from importlib.metadata import version

        versions["vibsynth"] = version("vibsynth") + _git_describe()
    except Exception:
        versions["vibsynth"] = _git_describe()
    mem = ""
    try:
        mem = Path("/proc/meminfo").read_text().splitlines()[0].split(":", 1)[1].strip()
    except OSError:
        pass
    return {
        "cpu_model": model,
        "cores": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)),
        "kernel": platform.release(),
        "platform": platform.platform(),
        "memory": mem,
        "loadavg_at_start": os.getloadavg(),
        "versions": versions,
    }


def _fmt(v, spec: str = ".1f") -> str:
    return "-" if v is None else format(v, spec)


def _ci(lat: dict) -> str:
    ci = lat.get("median_ci95_ms")
    return f"[{ci[0]:.2f}, {ci[1]:.2f}]" if ci else "-"


def _print_head(head: str) -> None:
    print(head)
    print("-" * len(head))


def print_table(peers: dict, idle: dict | None = None) -> None:
    _print_head(
        f"{'peer':<12} {'phase':<8} {'CPU %':>6} {'DSP %':>6} {'xruns':>5} {'underfl':>7} {'drv late':>8} "
        f"{'lat med':>7} {'95% CI':>12} {'lat p95':>7} {'n':>4}  {'sent/s':>7}"
    )
    for peer, entry in peers.items():
        if "skipped" in entry:
            print(f"{peer:<12} SKIPPED: {entry['skipped']}")
            continue
        base = entry.get("baseline")
        if base:
            print(
                f"{peer:<12} {'(jack)':<8} {'-':>6} {_fmt(base['dsp_load_mean_pct']):>6} {'-':>5} {'-':>7} "
                f"{base['driver_late_wakeups']:>8}"
            )
        for phase, r in entry.get("phases", {}).items():
            w, tot, lat = r["window"], r.get("phase_total", r["window"]), r.get("latency", {})
            sent = r.get("sender", {}).get("rate")
            print(
                f"{peer:<12} {phase:<8} {_fmt(w['cpu_pct']):>6} {_fmt(w['dsp_load_mean_pct']):>6} "
                f"{tot['target_late_cycles']:>5} {_fmt(w.get('status_underflows'), 'd'):>7} "
                f"{tot['driver_late_wakeups']:>8} {_fmt(lat.get('median_ms'), '.2f'):>7} {_ci(lat):>12} "
                f"{_fmt(lat.get('p95_ms'), '.2f'):>7} {lat.get('trials', 0):>4}  {_fmt(sent, '.0f'):>7}"
            )
        if "error" in entry:
            print(f"{peer:<12} FAILED: {entry['error'].splitlines()[0]}")
    print(
        "CPU % = target process (all threads), % of one core, over the window; DSP % = JACK's load (mean); "
        "xruns = cycles jackd reports the target's client late (window + latency trials); underfl = vibsynth "
        "/status underflows in the window (PortAudio counts every xrun of the server, so during the trials it "
        "also counts the capture client's); drv late = the dummy driver's own late wake-ups (window + trials; "
        "(jack) = the server alone before the target starts); latency ms, OSC send -> first output sample "
        "(n trials; idle: interleaved rounds), median with its 95 % order-statistic interval."
    )
    if idle:
        print_idle(peers, idle)


def print_idle(peers: dict, idle: dict) -> None:
    """The interleaved idle latency: per peer, then vibsynth against the peers."""
    st = idle["stage"]
    print(
        f"\nIdle latency, {st['rounds']} rounds interleaved ({st['seconds']:.0f} s; load average "
        f"{st['loadavg_before'][0]:.2f} -> {st['loadavg_after'][0]:.2f}; machine busy "
        f"{st['machine_busy_pct_of_all_cores']:.0f} % of all cores, per round p10/p50/p90 "
        + "/".join(f"{v:.0f}" for v in st["machine_busy_pct_per_round_p10_p50_p90"])
        + " %)"
    )
    _print_head(
        f"{'peer':<12} {'median':>7} {'95% CI':>14} {'mean':>6} {'wait':>6} {'excess':>7} "
        f"{'cur':>5} {'next':>5} {'miss':>5} {'n':>4}"
    )
    for peer, entry in peers.items():
        lat = entry.get("phases", {}).get("idle", {}).get("latency")
        if not lat or not lat.get("interleaved") or not lat.get("trials"):
            continue
        hist = lat["cycle_taken"]
        placed = max(1, hist["-1"] + hist["0"] + hist["1"] + hist["2"])
        print(
            f"{peer:<12} {lat['median_ms']:>7.3f} {_ci(lat).replace(', ', ','):>14} {lat['mean_ms']:>6.3f} "
            f"{_fmt(lat['wait_to_next_cycle']['mean_ms'], '.3f'):>6} {_fmt(lat['excess_mean_ms'], '.3f'):>7} "
            f"{100 * hist['-1'] / placed:>4.0f}% {100 * hist['0'] / placed:>4.0f}% "
            f"{100 * (hist['1'] + hist['2']) / placed:>4.0f}% {lat['trials']:>4}"
        )
    print(
        "ms; wait = send -> start of the next cycle (mean); excess = latency - wait (mean); the cycle that took the "
        "message: cur = the one running at the send (its callback started after the send), next = the next one, "
        "miss = a later one."
    )
    cmp_ = idle.get("comparison")
    if cmp_:
        r, d = cmp_["ratio_to_better_peer"], cmp_["difference_to_better_peer_ms"]
        print(
            f"vibsynth / better peer ({cmp_['better_peer']}), median: {r[0]:.3f}x [{r[1]:.3f}, {r[2]:.3f}], "
            f"{d[0]:+.3f} ms [{d[1]:+.3f}, {d[2]:+.3f}]"
        )
        for peer, c in cmp_["per_peer"].items():
            r, d = c["ratio"], c["difference_ms"]
            print(f"vibsynth / {peer}: {r[0]:.3f}x [{r[1]:.3f}, {r[2]:.3f}], {d[0]:+.3f} ms [{d[1]:+.3f}, {d[2]:+.3f}]")
        for peer, c in cmp_.get("excess_difference_ms", {}).items():
            e = cmp_["excess_mean_ms"]
            print(
                f"excess (latency - wait to the next cycle), mean: vibsynth {e['vibsynth'][0]:.3f} ms, {peer} "
                f"{e[peer][0]:.3f} ms; difference {c[0]:+.3f} ms [{c[1]:+.3f}, {c[2]:+.3f}]"
            )
        print(f"({cmp_['interval']})")


# ------------------------------------------------------------------ child entry points
def pyo_child(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--jackname", required=True)
    p.add_argument("--rate", type=int, default=48000)
    p.add_argument("--period", type=int, default=128)
    a = p.parse_args(argv)
    stop_event = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop_event.set())
    signal.signal(signal.SIGINT, lambda *_: stop_event.set())
    import pyo

    s = pyo.Server(sr=a.rate, nchnls=1, buffersize=a.period, duplex=0, audio="jack", jackname=a.jackname)
    s.setJackAuto(False, False)
    s.deactivateMidi()
    s.boot()
    if not s.getIsBooted():
        print("pyo server did not boot", flush=True)
        return 3
    addresses = [PYO_AMP] + [PYO_GAIN.format(k) for k in range(N_BANDS)]
    rx = pyo.OscReceive(port=a.port, address=addresses)
    rx.setInterpolation(False)
    noise = pyo.Noise()
    bands = [pyo.ButBP(noise, freq=f, q=1.0 / RQ, mul=rx[PYO_GAIN.format(k)]) for k, f in enumerate(CENTRES)]
    mix = pyo.Mix(bands, voices=1, mul=rx[PYO_AMP]).out()
    s.start()
    print("PEER-READY", pyo.PYO_VERSION if hasattr(pyo, "PYO_VERSION") else "?", flush=True)
    while not stop_event.wait(0.5):
        pass
    s.stop()
    time.sleep(0.2)
    del mix, bands, noise, rx
    s.shutdown()
    return 0


def flood_child(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--rate", type=int, required=True)
    p.add_argument("--max-seconds", type=float, required=True)
    p.add_argument("--messages", type=Path, required=True)
    a = p.parse_args(argv)
    raw = a.messages.read_bytes()
    msgs, pos = [], 0
    while pos < len(raw):
        n = struct.unpack_from(">I", raw, pos)[0]
        msgs.append(raw[pos + 4 : pos + 4 + n])
        pos += 4 + n
    stop_flag = []
    signal.signal(signal.SIGTERM, lambda *_: stop_flag.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop_flag.append(1))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = ("127.0.0.1", a.port)
    per_ms = max(1, a.rate // 1000)
    sent = errors = 0
    start = time.perf_counter()
    next_t = start
    while not stop_flag and next_t < start + a.max_seconds:
        for _ in range(per_ms):
            try:
                sock.sendto(msgs[sent % len(msgs)], target)
            except OSError:
                errors += 1
            sent += 1
        next_t += per_ms / a.rate
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    elapsed = time.perf_counter() - start
    print(
        json.dumps(
            {"sent": sent, "seconds": elapsed, "rate": sent / elapsed if elapsed else 0.0, "send_errors": errors}
        ),
        flush=True,
    )
    return 0


# ------------------------------------------------------------------ the run
def _sum_windows(*windows: dict) -> dict:
    keys = ("target_late_cycles", "other_clients_late", "driver_late_wakeups", "process_errors", "xrun_callbacks")
    return {k: sum(int(w.get(k, 0)) for w in windows) for k in keys}


def run_stages(runs: list[PeerRun], args, result: dict) -> None:
    """Idle windows (one peer after the other), the interleaved idle latency trials (all peers),
    then the flood phases (one peer after the other). Every peer streams throughout."""
    for run in [r for r in runs if r.ok]:
        print(f"  {run.peer}: idle window ({args.seconds:g} s)", flush=True)
        try:
            run.entry["phases"]["idle"] = {"phase": "idle", "window": measure_window(run, args.seconds, None)}
        except Exception as exc:
            run.fail(exc)
    live = [r for r in runs if r.ok]
    if live and args.idle_trials > 0:
        print(
            f"  idle latency: {args.idle_trials} rounds x {len(live)} peers ({', '.join(r.peer for r in live)}), "
            f"interleaved in random order",
            flush=True,
        )
        got = interleaved_idle_latency(live, args)
        stage, trials = got["stage"], got["trials"]
        for run in live:
            phase = run.entry["phases"]["idle"]
            phase["latency"] = dict(summarise_trials(trials[run.peer], args.latency_clock), interleaved=True)
            phase["latency"]["trial_log"] = trial_log(trials[run.peer])
            phase["latency_window"] = stage["windows"][run.peer]
            phase["phase_total"] = _sum_windows(phase["window"], phase["latency_window"])
        result["idle_latency"] = {
            "stage": {k: v for k, v in stage.items() if k != "windows"},
            "comparison": compare_idle(trials, args.idle_trials, args.latency_clock),
        }
    for run in [r for r in runs if r.ok]:
        print(f"  {run.peer}: flood ({args.seconds:g} s + {args.trials} latency trials)", flush=True)
        try:
            run.entry["phases"]["flood"] = flood_phase(run, args, run.tmp)
        except Exception as exc:
            run.fail(exc)


_SCALARS = re.compile(r"\[\s+((?:-?[0-9.eE+-]+|null|true|false)(?:,\s+(?:-?[0-9.eE+-]+|null|true|false))*)\s+\]")


def compact_json(obj) -> str:
    """JSON indented by 2, but each list of numbers on one line (the trial logs stay readable)."""
    return _SCALARS.sub(lambda m: "[" + " ".join(m.group(1).split()) + "]", json.dumps(obj, indent=2))


# ------------------------------------------------------------------ main
class BenchTimeout(BaseException):
    """Raised by SIGALRM (--timeout); not an Exception, so no per-peer handler swallows it."""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_pyo_child"]:
        return pyo_child(argv[1:])
    if argv[:1] == ["_flood"]:
        return flood_child(argv[1:])
    if argv[:1] == ["_jack_agent"]:
        return jack_agent(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="measurement window per phase (default 10)")
    parser.add_argument(
        "--idle-trials",
        type=int,
        default=800,
        help="idle latency rounds: one trial of every peer per round, interleaved (default 800; 0 = none)",
    )
    parser.add_argument(
        "--trials", type=int, default=50, help="latency trials under the flood, per peer (default 50; 0 = none)"
    )
    parser.add_argument(
        "--gap",
        type=float,
        default=0.05,
        help="seconds of silence before, and of sound after, each send",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the interleaving order and phases (default 0)")
    parser.add_argument(
        "--phase",
        choices=("stratified", "free"),
        default="stratified",
        help="idle trials: send at a stratified fraction of the cycle, the same for every peer of a round "
        "(default), or whenever the gap ends (free)",
    )
    parser.add_argument("--rate", type=int, default=10000, help="flood rate, OSC messages/s (default 10000)")
    parser.add_argument("--only", default=",".join(PEERS), help="comma-separated subset of: " + ", ".join(PEERS))
    parser.add_argument(
        "--vibsynth-flood",
        choices=("balance", "texture", "intensity"),
        default="balance",
        help="what the flood sends to vibsynth (default balance; the others set the level, so "
        "no latency is measured under them)",
    )
    parser.add_argument(
        "--latency-clock",
        choices=("wall", "frame"),
        default="wall",
        help="clock of the latency columns (both are in the JSON; default wall, see latency_trials)",
    )
    parser.add_argument(
        "--vibsynth-src",
        type=Path,
        default=None,
        metavar="DIR",
        help="run vibsynth from this source folder (its C core already built in place) instead of the working tree",
    )
    parser.add_argument(
        "--vibsynth-ref",
        type=Path,
        default=None,
        metavar="DIR",
        help="also run a second vibsynth, 'vibsynth-ref', from this source folder (C core built in place), "
        "interleaved with the others: before/after under the same load",
    )
    parser.add_argument(
        "--vibsynth-rev",
        default=None,
        metavar="REV",
        help="run vibsynth from `git archive REV` (C core built in a temporary folder) instead "
        "of the working tree, e.g. HEAD while the tree is being edited",
    )
    parser.add_argument("--jack-rate", type=int, default=48000)
    parser.add_argument("--jack-period", type=int, default=128)
    parser.add_argument("--warmup", type=float, default=2.0, help="seconds of streaming before measuring")
    parser.add_argument(
        "--baseline",
        type=float,
        default=5.0,
        help="seconds of the JACK server alone before each peer starts (its own xruns; 0 = skip)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=None,
        help="hard bound on the whole run, s (default: 2 x the expected time + 120)",
    )
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument(
        "--no-merge", action="store_true", help="do not keep entries of peers not run now from an existing JSON file"
    )
    args = parser.parse_args(argv)
    peers = [p.strip() for p in args.only.split(",") if p.strip()]
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        parser.error(f"unknown peer(s) {unknown}; choose from {', '.join(PEERS)}")
    if args.vibsynth_ref is not None:
        peers.append(REFERENCE)
    for tool in ("jackd", "jack_wait"):
        if shutil.which(tool) is None:
            print(f"bench_peers: {tool} not found (Debian: apt-get install jackd2)", file=sys.stderr)
            return 2
    try:
        import jack  # noqa: F401
    except Exception as exc:
        print(f"bench_peers: the JACK-Client Python module is not usable ({exc})", file=sys.stderr)
        return 2

    expected = len(peers) * (25 + args.warmup + args.baseline + 2 * args.seconds + args.trials * 2 * args.gap + 4)
    expected += args.idle_trials * len(peers) * (2 * args.gap + 0.02)
    timeout = args.timeout or 2 * expected + 120

    def on_alarm(*_):
        raise BenchTimeout(f"run exceeded --timeout {timeout:.0f} s")

    def on_term(*_):
        raise KeyboardInterrupt

    signal.signal(signal.SIGALRM, on_alarm)
    signal.signal(signal.SIGINT, signal.default_int_handler)  # even if started with SIGINT ignored
    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGHUP, on_term)
    signal.alarm(int(math.ceil(timeout)))

    gains, gains_origin = band_gains()
    result = {
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": machine_info(),
        "settings": {
            "seconds": args.seconds,
            "trials": args.trials,
            "flood_rate": args.rate,
            "jack_rate": args.jack_rate,
            "jack_period": args.jack_period,
            "channels": 1,
            "bands": N_BANDS,
            "centres_hz": [round(f, 3) for f in CENTRES],
            "rq": RQ,
            "band_gains": gains,
            "band_gains_origin": gains_origin,
            "vibsynth_flood": args.vibsynth_flood,
            "latency_gap_s": args.gap,
            "idle_trials": args.idle_trials,
            "seed": args.seed,
            "silent_threshold": SILENT_THRESHOLD,
        },
        "peers": {},
    }
    print(
        f"bench_peers: {', '.join(peers)}; {args.seconds:g} s windows, {args.idle_trials} interleaved idle latency "
        f"rounds, {args.trials} latency trials under a {args.rate} msg/s flood, JACK dummy {args.jack_rate} Hz / "
        f"{args.jack_period}; load {os.getloadavg()[0]:.2f}; bound {timeout:.0f} s",
        flush=True,
    )
    status = 0
    try:
        with tempfile.TemporaryDirectory(prefix="bench-peers-") as tmpdir:
            tmp = Path(tmpdir)
            args.vibsynth_src_dir, args.vibsynth_source = None, "working tree" + _git_describe()
            if args.vibsynth_rev and "vibsynth" in peers:
                args.vibsynth_src_dir, args.vibsynth_source = vibsynth_snapshot(args.vibsynth_rev, tmp)
            elif args.vibsynth_src:
                args.vibsynth_src_dir = args.vibsynth_src.resolve()
                args.vibsynth_source = f"source folder {args.vibsynth_src_dir}"
            result["settings"]["vibsynth_source"] = args.vibsynth_source if "vibsynth" in peers else None
            if args.vibsynth_ref is not None:
                result["settings"]["vibsynth_ref_source"] = str(args.vibsynth_ref.resolve())
            if "vibsynth" in peers:
                result["machine"]["versions"]["vibsynth"] = args.vibsynth_source
            runs = []
            try:
                for peer in peers:
                    missing = peer_missing(peer)
                    if missing:
                        print(f"  {peer}: SKIPPED: {missing}", flush=True)
                        result["peers"][peer] = {"peer": peer, "skipped": missing}
                        continue
                    run = PeerRun(peer, args, tmp, gains)
                    runs.append(run)
                    result["peers"][peer] = run.entry
                    print(f"  {peer}: starting", flush=True)
                    try:
                        run.start()
                    except Exception as exc:
                        run.fail(exc)
                run_stages(runs, args, result)
            except (KeyboardInterrupt, BenchTimeout) as exc:
                for run in runs:
                    if run.ok and not run.stopped:
                        run.entry["error"] = f"interrupted ({str(exc) or 'Ctrl-C or SIGTERM'})"
                raise
            finally:
                for run in runs:
                    try:
                        run.stop()
                    except Exception as exc:
                        print(f"bench_peers: stopping {run.peer}: {exc}", file=sys.stderr)
            if any(not run.ok for run in runs):
                status = 1
    except (KeyboardInterrupt, BenchTimeout) as exc:
        print(f"\nbench_peers: interrupted ({str(exc) or 'Ctrl-C or SIGTERM'}); stopping everything", file=sys.stderr)
        status = 130 if isinstance(exc, KeyboardInterrupt) else 3
    finally:
        signal.alarm(0)
        stop_all()
    if not result["peers"]:
        return status
    print()
    print_table(result["peers"], result.get("idle_latency"))
    out = dict(result)
    if not args.no_merge and args.json.exists():
        try:
            old = json.loads(args.json.read_text(encoding="utf-8"))
            old_peers = old.get("peers", {})
            kept = {p: e for p, e in old_peers.items() if p not in result["peers"]}
            # a peer that failed now keeps its last good entry, with the failure noted in it
            for p, e in result["peers"].items():
                prev = old_peers.get(p)
                if "error" in e and prev and "phases" in prev and "error" not in prev:
                    kept[p] = dict(prev, last_failed_attempt={"when": e.get("when"), "error": e["error"]})
            for e in kept.values():
                e.setdefault("machine", old.get("machine"))
                e.setdefault("settings", old.get("settings"))
                e["kept_from_run_of"] = e.get("kept_from_run_of", old.get("when"))
            if kept:
                out["peers"] = {**result["peers"], **kept}
                out["peers"] = {p: out["peers"][p] for p in (*PEERS, REFERENCE) if p in out["peers"]}
                print(f"(kept from {args.json.name}: {', '.join(kept)})")
        except (OSError, ValueError) as exc:
            print(f"bench_peers: not merging with {args.json} ({exc})", file=sys.stderr)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(compact_json(out), encoding="utf-8")
    print(f"\nJSON: {args.json}")
    return status


if __name__ == "__main__":
    sys.exit(main())
