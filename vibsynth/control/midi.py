"""MIDI input for ``vibsynth serve``: ports, the input thread, learn, and offline MIDI-file rendering.

The mapping itself (message -> knob) lives in :mod:`vibsynth.control.midi_mapping`;
this module only moves messages from a port (or a file) into a :class:`MidiMapper`.

Backend
-------
Ports come from mido's backend, chosen by mido's usual ``MIDO_BACKEND``
environment variable (default python-rtmidi with the platform's API: ALSA on
Linux, CoreMIDI on macOS, WinMM on Windows; ``mido.backends.rtmidi/UNIX_JACK``
for JACK MIDI). Nothing here names a backend.

Input thread
------------
The port is opened through mido, then read by polling on a thread of our own
(for python-rtmidi: its C++ queue, so no Python code runs inside the MIDI
backend's thread, which for JACK is the real-time process thread). The thread
calls the mapper, which calls the :class:`Controller`, which only appends to the
engine's command deque: the input thread never waits for the audio thread.

Disconnects
-----------
A named (non-virtual) port is checked every ``midi.reconnect_interval_s``
(default 1 s). When it vanishes, every note it was holding is released (no stuck
notes on the channels it drove) and the port is reopened as soon as a port of
that name reappears.
"""
from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import mido

from vibsynth.control.midi_mapping import KNOBS, Binding, MidiMapper, MidiSettings, check_learn_knob
from vibsynth.errors import DeviceError, ParameterError

__all__ = [
    "VIRTUAL_PORT_NAME",
    "add_arguments",
    "create",
    "list_inputs",
    "learn",
    "active_servers",
    "MidiServer",
    "resolve_port_name",
    "save_learned_mapping",
    "user_config_path",
    "render_midi_file",
]

log = logging.getLogger(__name__)

VIRTUAL_PORT_NAME = "vibsynth"
POLL_S = 0.0005            # input thread sleep when the queue is empty
_ACTIVE: list["MidiServer"] = []
_ACTIVE_LOCK = threading.Lock()


# ---------------------------------------------------------------------- adapter contract
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the MIDI flags of ``vibsynth serve``."""
    group = parser.add_argument_group("MIDI")
    group.add_argument("--midi", metavar="NAME|INDEX", default=None,
                       help="open this MIDI input (name substring or index from `vibsynth devices`)")
    group.add_argument("--midi-virtual", action="store_true",
                       help=f"create a virtual MIDI input named {VIRTUAL_PORT_NAME!r} (ALSA, CoreMIDI, JACK)")
    group.add_argument("--no-midi", action="store_true", help="do not open any MIDI input")
    group.add_argument("--learn", metavar="KNOB", choices=KNOBS, default=None,
                       help="bind the next moved MIDI controller to KNOB (intensity|balance) "
                            "and save it to the user config file")


def list_inputs() -> list[str]:
    """Names of the MIDI inputs of mido's backend; empty when no backend is usable."""
    try:
        return list(mido.get_input_names())
    except Exception as exc:  # backend missing or its server not running: nothing to list
        log.debug("no MIDI inputs: %s", exc)
        return []


def create(config: Any, args: argparse.Namespace, controller: Any, presets: Any) -> "MidiServer | None":
    """Build (not start) the MIDI server from config and flags, or None (after one log line).

    Parameters
    ----------
    config : vibsynth.config.Config
    args : argparse.Namespace
        ``midi``, ``midi_virtual``, ``no_midi``, ``learn`` (absent = defaults); ``config`` (user file).
    controller : Controller
    presets : preset library or None

    Returns
    -------
    server : MidiServer or None

    Raises
    ------
    ConfigError
        The ``midi:`` section is invalid.
    """
    data = config.data
    section = data.get("midi") or {}
    if getattr(args, "no_midi", False) or not section.get("enabled", True):
        log.info("running without MIDI: disabled (%s)", "--no-midi" if getattr(args, "no_midi", False)
                 else "midi.enabled is false")
        return None
    port = getattr(args, "midi", None)
    port = section.get("port") if port is None else port
    virtual = bool(getattr(args, "midi_virtual", False) or (port is None and section.get("virtual", False)))
    if port is None and not virtual:
        log.warning("running without MIDI: no input chosen (use --midi NAME|INDEX or --midi-virtual)")
        return None
    settings = MidiSettings.from_config(data, controller.channels)
    try:
        names = mido.get_input_names()
    except Exception as exc:
        log.warning("running without MIDI: the MIDI backend is not usable (%s)", _one_line(exc))
        return None
    if not virtual:
        try:
            resolve_port_name(port, names)
        except DeviceError as exc:
            log.warning("running without MIDI: %s", exc)
            return None
    mapper = MidiMapper(controller, settings, presets=presets)
    server = MidiServer(
        mapper,
        port=port,
        virtual=virtual,
        config_path=user_config_path(getattr(args, "config", None)),
        reconnect_interval_s=float(section.get("reconnect_interval_s", 1.0) or 1.0),
    )
    if getattr(args, "learn", None):
        server.learn(args.learn)
    return server


def learn(knob: str) -> bool:
    """Arm MIDI learn for ``knob`` on every running MIDI server (hook for OSC ``/vibsynth/learn s``).

    Returns
    -------
    armed : bool
        False when no MIDI server is running.

    Raises
    ------
    ParameterError
        Unknown knob.
    """
    check_learn_knob(knob)
    servers = active_servers()
    for server in servers:
        server.learn(knob)
    return bool(servers)


def active_servers() -> list["MidiServer"]:
    """The MIDI servers started and not yet stopped in this process."""
    with _ACTIVE_LOCK:
        return list(_ACTIVE)


# ---------------------------------------------------------------------- ports
def resolve_port_name(spec: str | int, names: Sequence[str]) -> str:
    """The input name chosen by an index or a (case-insensitive) name substring.

    Raises
    ------
    DeviceError
        No such index or no name contains the substring.
    """
    text = str(spec).strip()
    if text.lstrip("-").isdigit():
        index = int(text)
        if 0 <= index < len(names):
            return names[index]
        raise DeviceError(f"MIDI input index {index} does not exist ({len(names)} inputs: {list(names)})")
    if text in names:
        return text
    for name in names:
        if text.lower() in name.lower():
            return name
    raise DeviceError(f"no MIDI input matches {text!r} (inputs: {list(names) or 'none'})")


def user_config_path(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The config file MIDI learn writes to: ``--config`` if given, else the platform config folder's ``config.yaml``."""
    if explicit:
        return Path(explicit)
    try:
        import platformdirs

        return Path(platformdirs.user_config_dir("vibsynth")) / "config.yaml"
    except ImportError:  # pragma: no cover - platformdirs is a dependency
        return Path.home() / ".config" / "vibsynth" / "config.yaml"


def save_learned_mapping(path: str | os.PathLike[str], bindings: Iterable[Binding], knobs: Iterable[str] = KNOBS) -> None:
    """Write ``midi.mapping.<knob>`` for ``knobs`` into a YAML file, keeping its comments and other keys.

    Uses ruamel.yaml round-trip mode through :func:`vibsynth.io.load_yaml` (the one YAML
    loader: size cap, no aliases, bounded nesting); the file (and its folder) is created
    when missing; the write goes through :func:`vibsynth.io.atomic_write` (a crash leaves
    the old file or the new one; the file keeps its mode). Bindings that come from
    ``midi.nrpn`` shorthand keys are written as ``{nrpn: [msb, lsb]}`` entries only if
    they were learned.

    Parameters
    ----------
    path : path
    bindings : iterable of Binding
        The full current bindings.
    knobs : iterable of str
        Knobs whose lists are (re)written.

    Raises
    ------
    ConfigError
        The existing file is over the size cap, holds a YAML alias or a syntax error
        (named by file and line; nothing is written).
    OSError
        The file cannot be written (the old one is untouched).
    """
    import io as _io

    from ruamel.yaml import YAML
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    from vibsynth.errors import ConfigError
    from vibsynth.io import atomic_write, load_yaml

    path = Path(path)
    doc = None
    if path.exists():
        doc = load_yaml(path, round_trip=True, error=ConfigError, what="a config file").data
    if doc is None:
        doc = CommentedMap()
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: the config must be a mapping of sections, not {type(doc).__name__}")
    midi = doc.get("midi")
    if midi is None:
        midi = doc["midi"] = CommentedMap()
    mapping = midi.get("mapping")
    if mapping is None:
        mapping = midi["mapping"] = CommentedMap()
    bindings = list(bindings)
    for knob in knobs:
        entries = CommentedSeq()
        for b in bindings:
            if b.knob == knob and (b.cc is not None or b.nrpn is not None):
                item = CommentedMap(b.to_config())
                item.fa.set_flow_style()
                entries.append(item)
        entries.fa.set_flow_style()
        mapping[knob] = entries
    text = _io.StringIO()
    YAML().dump(doc, text)  # round-trip dumper: comments and layout kept
    atomic_write(path, text.getvalue())


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


# ---------------------------------------------------------------------- server
class MidiServer:
    """A MIDI input feeding a :class:`MidiMapper` from its own thread.

    Parameters
    ----------
    mapper : MidiMapper
    port : str or int or None
        Input name substring or index (ignored when ``virtual``).
    virtual : bool
        Create a virtual input named :data:`VIRTUAL_PORT_NAME` instead.
    config_path : path, optional
        Where learned bindings are saved (None: not saved).
    reconnect_interval_s : float
        How often a named port is checked for disconnects / reopened.
    open_input : callable, optional
        ``(name, virtual) -> mido port``; default ``mido.open_input`` (tests inject fakes).
    input_names : callable, optional
        Default ``mido.get_input_names``.
    """

    name = "midi"

    def __init__(
        self,
        mapper: MidiMapper,
        *,
        port: str | int | None = None,
        virtual: bool = False,
        config_path: str | os.PathLike[str] | None = None,
        reconnect_interval_s: float = 1.0,
        open_input: Callable[[str, bool], Any] | None = None,
        input_names: Callable[[], list[str]] | None = None,
    ) -> None:
        self.mapper = mapper
        self.port_spec = port
        self.virtual = virtual
        self.config_path = None if config_path is None else Path(config_path)
        self.reconnect_interval_s = max(0.05, float(reconnect_interval_s))
        self._open_input = open_input or self._mido_open
        self._input_names = input_names or (lambda: list(mido.get_input_names()))
        self._lock = threading.Lock()            # mapper access: input thread vs watcher/learn
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._port: Any = None
        self._port_name: str | None = None
        self.disconnects = 0
        self.received = 0
        self.last_message_at: float | None = None
        self.learned: list[Binding] = []

    # -------------------------------------------------------------- lifecycle
    @staticmethod
    def _mido_open(name: str, virtual: bool) -> Any:
        if virtual:
            return mido.open_input(name, virtual=True, client_name=VIRTUAL_PORT_NAME)
        return mido.open_input(name)

    def _open(self) -> None:
        if self.virtual:
            port = self._open_input(VIRTUAL_PORT_NAME, True)
            name = VIRTUAL_PORT_NAME
        else:
            name = resolve_port_name(self.port_spec if self.port_spec is not None else 0, self._input_names())
            port = self._open_input(name, False)
        rt = getattr(port, "_rt", None)
        if rt is not None:  # python-rtmidi: poll its queue, never run Python in the backend's thread
            port.callback = None
            rt.cancel_callback()
        self._port, self._port_name = port, name

    def start(self) -> None:
        """Open the port and start the input thread.

        Raises
        ------
        DeviceError
            The port cannot be opened.
        """
        try:
            self._open()
        except DeviceError:
            raise
        except Exception as exc:
            raise DeviceError(f"cannot open MIDI input: {_one_line(exc)}") from exc
        self._stop.clear()
        reader = threading.Thread(target=self._read_loop, name="vibsynth-midi-in", daemon=True)
        self._threads = [reader]
        if not self.virtual:
            self._threads.append(threading.Thread(target=self._watch_loop, name="vibsynth-midi-watch", daemon=True))
        for t in self._threads:
            t.start()
        with _ACTIVE_LOCK:
            _ACTIVE.append(self)
        log.info("%s", self.describe())

    def stop(self) -> None:
        """Release held notes, stop the threads and close the port."""
        self._stop.set()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._threads = []
        with self._lock:
            self.mapper.release_all()
        self._close_port()
        with _ACTIVE_LOCK:
            if self in _ACTIVE:
                _ACTIVE.remove(self)

    def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except Exception as exc:  # a vanished device may fail to close; nothing to do
                log.debug("closing MIDI input: %s", exc)

    def describe(self) -> str:
        """One line for the start-up banner."""
        where = f"virtual input {VIRTUAL_PORT_NAME!r}" if self.virtual else f"input {self._port_name or self.port_spec!r}"
        backend = getattr(self._port, "_device_type", None) or str(getattr(mido, "backend", "")).split(" (")[0]
        learn = f", learning {self.mapper.learning}" if self.mapper.learning else ""
        return f"MIDI on {where} ({backend}), mode {self.mapper.settings.mode}{learn}"

    # -------------------------------------------------------------- learn
    def learn(self, knob: str) -> None:
        """Bind the next moved controller to ``knob`` and save it to the user config file."""
        self.mapper.learn(knob, self._learned)
        log.warning("MIDI learn: move a controller to bind it to %s", knob)

    def _learned(self, binding: Binding, bindings: tuple[Binding, ...]) -> None:
        self.learned.append(binding)
        what = f"CC {binding.cc}" if binding.cc is not None else f"NRPN {binding.nrpn}"
        log.warning("MIDI learn: %s -> %s", what, binding.knob)
        if self.config_path is None:
            return
        path = self.config_path
        # file I/O off the input thread
        threading.Thread(target=self._save, args=(path, bindings), name="vibsynth-midi-learn", daemon=True).start()

    def _save(self, path: Path, bindings: tuple[Binding, ...]) -> None:
        try:
            save_learned_mapping(path, bindings)
            log.warning("MIDI learn: saved to %s", path)
        except Exception as exc:
            log.error("MIDI learn: could not save to %s: %s", path, _one_line(exc))

    # -------------------------------------------------------------- threads
    def _read_loop(self) -> None:
        while not self._stop.is_set():
            port = self._port
            if port is None:
                self._stop.wait(0.01)
                continue
            got = False
            try:
                rt = getattr(port, "_rt", None)
                if rt is not None:
                    while True:
                        item = rt.get_message()
                        if not item:
                            break
                        got = True
                        self._feed_bytes(item[0])
                else:
                    for msg in port.iter_pending():
                        got = True
                        self._feed(msg)
            except Exception as exc:  # a failing port: the watcher decides about reconnecting
                log.debug("MIDI read error: %s", exc)
                self._stop.wait(0.01)
            if not got:
                time.sleep(POLL_S)

    def _feed_bytes(self, data: Sequence[int]) -> None:
        self.received += 1
        self.last_message_at = time.monotonic()
        with self._lock:
            self.mapper.handle_bytes(data)

    def _feed(self, msg: mido.Message) -> None:
        self.received += 1
        self.last_message_at = time.monotonic()
        with self._lock:
            self.mapper.handle(msg)

    def _list_names(self) -> list[str]:
        # While open, list through the port's own rtmidi object: creating a new backend
        # client (what mido.get_input_names does) while holding the GIL can deadlock
        # against an in-process JACK audio callback.
        rt = getattr(self._port, "_rt", None)
        if rt is not None:
            return list(rt.get_ports())
        return self._input_names()

    def _watch_loop(self) -> None:
        while not self._stop.wait(self.reconnect_interval_s):
            try:
                names = self._list_names()
            except Exception as exc:
                log.debug("listing MIDI inputs failed: %s", exc)
                names = []
            if self._port is not None and self._port_name not in names:
                self._disconnected()
            elif self._port is None:
                try:
                    self._open()
                    log.warning("MIDI input %r is back", self._port_name)
                except Exception:
                    pass

    def _disconnected(self) -> None:
        """The port vanished: release every note it held, close it, retry later."""
        self.disconnects += 1
        with self._lock:
            released = self.mapper.release_all()
        log.warning("MIDI input %r disconnected; released %d actuator channel(s); will reopen when it returns",
                    self._port_name, len(released))
        self._close_port()


# ---------------------------------------------------------------------- offline rendering
def _knob_limits(data: dict[str, Any]) -> Any:
    from vibsynth.control.controller import KnobLimits

    knobs = data.get("knobs") or {}
    return KnobLimits(balance_min=float(knobs.get("balance_min", -3.5)), balance_max=float(knobs.get("balance_max", 3.5)))


def render_midi_file(path: str | os.PathLike[str], *, config: Any, basis: Any = None, seconds: float | None = None,
                     presets: Any = None, block: int = 1024, engine: Any = None) -> tuple[Any, float]:
    """Render a MIDI file (CC automation and notes) offline through the live mapping.

    Every message is applied at its exact sample (``at_frame``), so the result
    is the same as playing the file into ``vibsynth serve`` with no jitter.

    Parameters
    ----------
    path : path
        Standard MIDI file (type 0 or 1; tempo changes honoured).
    config : vibsynth.config.Config
    basis : Basis, optional
        Passed to :func:`vibsynth.service.build_engine`.
    seconds : float, optional
        Output length; default the file's length plus the release time and 0.25 s.
    presets : preset library, optional
        For program changes.
    block : int
        Render block size (frames).
    engine : Engine, optional
        A fresh engine to render with (tests, benchmarks); default
        ``vibsynth.service.build_engine(config, basis=basis)``.

    Returns
    -------
    samples : ndarray, float32, shape (frames, channels)
    fs : float

    Raises
    ------
    InputError
        The file cannot be read as MIDI.
    """
    import numpy as np

    from vibsynth.control.controller import Controller
    from vibsynth.errors import InputError

    try:
        midi_file = mido.MidiFile(str(path))
    except (OSError, ValueError, EOFError, KeyError, IndexError) as exc:
        raise InputError(f"{path}: not a readable MIDI file ({_one_line(exc)})") from None
    data = config.data
    if engine is None:
        from vibsynth.service import build_engine

        engine = build_engine(config, basis=basis)
    knobs = data.get("knobs") or {}
    controller = Controller(engine, limits=_knob_limits(data),
                            initial_glide_s=float(knobs.get("glide_ms", 20.0)) / 1000.0,
                            preset_resolver=getattr(presets, "get", None))
    settings = MidiSettings.from_config(data, engine.channels)
    mapper = MidiMapper(controller, settings, presets=presets, source="midi-file")
    fs = float(engine.fs)
    events: list[tuple[int, mido.Message]] = []
    t = 0.0
    for msg in midi_file:  # iteration yields delta times in seconds (tempo applied)
        t += float(msg.time)
        if not msg.is_meta:
            events.append((int(round(t * fs)), msg))
    if seconds is None:
        seconds = t + settings.release_s + 0.25
    total = int(round(float(seconds) * fs))
    if total <= 0:
        raise ParameterError(f"render length must be positive, got {seconds!r} s")
    out = np.zeros((total, engine.channels), dtype=np.float32)
    i = 0
    pos = 0
    while pos < total:
        n = min(block, total - pos)
        while i < len(events) and events[i][0] < pos + n:
            mapper.handle(events[i][1], at_frame=max(events[i][0], pos))
            i += 1
        out[pos:pos + n] = engine.render(n)
        pos += n
    return out, fs
