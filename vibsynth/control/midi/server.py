"""MIDI input for ``vibsynth serve``: ports, the input thread, learn, and offline MIDI-file rendering.

The mapping itself (message -> knob) lives in :mod:`vibsynth.control.midi.mapper`;
this module only moves messages from a port (or a file) into a :class:`MidiMapper`.

Backend
-------
Ports come from mido's backend, chosen by mido's usual ``MIDO_BACKEND``
environment variable (default python-rtmidi with the platform's API: ALSA on
Linux, CoreMIDI on macOS, WinMM on Windows; ``mido.backends.rtmidi/UNIX_JACK``
for JACK MIDI). Nothing here names a backend.

Input thread
------------
The port is read by polling on a thread of our own. The thread calls the mapper,
which calls the :class:`Controller`, which only appends to the engine's command
deque: the input thread never waits for the audio thread.

With mido's default backend (``mido.backends.rtmidi``, python-rtmidi >=
:data:`RTMIDI_MIN_VERSION`) the port is opened through python-rtmidi's public API
(:class:`RtMidiInput`) with the backend API mido's ``MIDO_BACKEND`` names, and
polled with ``MidiIn.get_message()`` (its C++ queue). A port opened through mido
would install mido's Python callback in the backend's own thread, which for JACK
is the real-time process thread: every message would take the GIL there. With any
other backend, or an older python-rtmidi, the port is opened through mido and
polled with its public ``iter_pending()``.

Disconnects
-----------
A named (non-virtual) port is checked every ``midi.reconnect_interval_s``
(default 1 s). When it vanishes, every note it was holding is released (no stuck
notes on the channels it drove) and the port is reopened as soon as a port of
that name reappears.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import mido

from vibsynth.control.midi.bindings import Binding
from vibsynth.control.midi.learn_store import save_learned_mapping
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.tap import InputTap
from vibsynth.errors import DeviceError

log = logging.getLogger(__name__)

_ACTIVE: list[MidiServer] = []
_ACTIVE_LOCK = threading.Lock()


def running_servers() -> list[MidiServer]:
    """The MIDI servers started in this process and not yet stopped."""
    with _ACTIVE_LOCK:
        return list(_ACTIVE)


VIRTUAL_PORT_NAME = "vibsynth"
POLL_S = 0.0005  # input thread sleep when the queue is empty
#: Oldest python-rtmidi whose API :class:`RtMidiInput` uses (``get_api_name``, ``MidiIn(name=)``).
RTMIDI_MIN_VERSION = (1, 4)
_MIDO_RTMIDI = "mido.backends.rtmidi"


def _version_tuple(text: str) -> tuple[int, ...]:
    parts = []
    for part in text.split("."):
        digits = "".join(ch for ch in part if ch.isdigit()) if part[:1].isdigit() else ""
        if not digits:
            break
        parts.append(int(digits))
    return tuple(parts)


def rtmidi_module() -> Any:
    """python-rtmidi, when mido's backend is the rtmidi one and the version is supported; else None."""
    if mido.backend.name != _MIDO_RTMIDI:
        return None
    from importlib.metadata import PackageNotFoundError, version

    import rtmidi  # a dependency; imported here so libjack/libasound load only when MIDI is used

    try:
        installed = _version_tuple(version("python-rtmidi"))
    except PackageNotFoundError:  # no metadata (e.g. a vendored copy): mido's public API
        return None
    return rtmidi if installed >= RTMIDI_MIN_VERSION else None


class RtMidiInput:
    """A MIDI input opened and polled through python-rtmidi's public API (no callback).

    Parameters
    ----------
    rtmidi : module
        python-rtmidi (see :func:`rtmidi_module`).
    name : str
        Port to open (exactly as listed), or the virtual port's name.
    virtual : bool
        Create a virtual input (client and port both named ``name``).
    api : str, optional
        Backend API as mido names it (``UNIX_JACK``, ``LINUX_ALSA``, ...; ``MIDO_BACKEND``'s
        part after the slash); None = python-rtmidi's default.

    Raises
    ------
    OSError
        No such port, or the backend refused to open it.
    """

    def __init__(self, rtmidi: Any, name: str, *, virtual: bool, api: str | None = None) -> None:
        rtapi = rtmidi.API_UNSPECIFIED if api is None else getattr(rtmidi, f"API_{api}", None)
        if rtapi is None:
            raise OSError(f"unknown MIDI API {api!r}")
        try:
            self._midi = rtmidi.MidiIn(rtapi=rtapi, name=name if virtual else None)
        except Exception as exc:  # rtmidi.SystemError: no ALSA sequencer, no JACK server
            raise OSError(_one_line(exc)) from None
        try:
            if virtual:
                self._midi.open_virtual_port(name)
            else:
                ports = self._midi.get_ports()
                if name not in ports:
                    raise OSError(f"unknown port {name!r}")
                self._midi.open_port(ports.index(name))
        except Exception:
            self._midi.delete()
            raise
        self._midi.ignore_types(sysex=False, timing=False, active_sense=True)  # as mido does
        self.name = name
        self.backend = f"RtMidi/{rtmidi.get_api_name(self._midi.get_current_api())}"

    def iter_pending_bytes(self) -> Iterator[list[int]]:
        """The raw messages queued since the last call (python-rtmidi's C++ queue)."""
        while True:
            item = self._midi.get_message()
            if not item:
                return
            yield item[0]

    def port_names(self) -> list[str]:
        """The backend's input names, listed through this client (no new backend client)."""
        return list(self._midi.get_ports())

    def close(self) -> None:
        self._midi.close_port()
        self._midi.delete()


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


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


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
        ``(name, virtual) -> port``: an :class:`RtMidiInput` or a mido input port (read with
        ``iter_pending()``). Default: :class:`RtMidiInput` when :func:`rtmidi_module` allows
        it, else ``mido.open_input`` (tests inject fakes).
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
        tap: InputTap | None = None,
    ) -> None:
        self.mapper = mapper
        self.tap = tap if tap is not None else InputTap()
        self.port_spec = port
        self.virtual = virtual
        self.config_path = None if config_path is None else Path(config_path)
        self.reconnect_interval_s = max(0.05, float(reconnect_interval_s))
        self._open_input = open_input or self._mido_open
        self._input_names = input_names or (lambda: list(mido.get_input_names()))
        self._lock = threading.Lock()  # mapper access: input thread vs watcher/learn
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._port: Any = None
        self._port_name: str | None = None
        self.disconnects = 0
        self.received = 0
        self.learned: list[Binding] = []

    # -------------------------------------------------------------- lifecycle
    @staticmethod
    def _mido_open(name: str, virtual: bool) -> Any:
        rtmidi = rtmidi_module()
        if rtmidi is not None:
            return RtMidiInput(rtmidi, name, virtual=virtual, api=mido.backend.api)
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
        where = (
            f"virtual input {VIRTUAL_PORT_NAME!r}" if self.virtual else f"input {self._port_name or self.port_spec!r}"
        )
        backend = getattr(self._port, "backend", None) or mido.backend.name
        learn = f", learning {self.mapper.learning}" if self.mapper.learning else ""
        return f"MIDI on {where} ({backend}), mode {self.mapper.settings.mode}{learn}"

    # -------------------------------------------------------------- learn
    def learn(self, knob: str) -> None:
        """Bind the next moved controller to ``knob`` and save it to the user config file."""
        self.mapper.learn(knob, self._learned)
        log.info("MIDI learn: move a controller to bind it to %s", knob)

    def _learned(self, binding: Binding, bindings: tuple[Binding, ...]) -> None:
        self.learned.append(binding)
        what = f"CC {binding.cc}" if binding.cc is not None else f"NRPN {binding.nrpn}"
        log.info("MIDI learn: %s -> %s", what, binding.knob)
        if self.config_path is None:
            return
        path = self.config_path
        # file I/O off the input thread
        threading.Thread(target=self._save, args=(path, bindings), name="vibsynth-midi-learn", daemon=True).start()

    def _save(self, path: Path, bindings: tuple[Binding, ...]) -> None:
        try:
            save_learned_mapping(path, bindings)
            log.info("MIDI learn: saved to %s", path)
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
                if isinstance(port, RtMidiInput):
                    for data in port.iter_pending_bytes():
                        got = True
                        self._feed_bytes(data)
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
        if self.tap.active:
            self.tap.publish("midi", lambda: self._describe(mido.Message.from_bytes(list(data))))
        with self._lock:
            self.mapper.handle_bytes(data)

    def _feed(self, msg: mido.Message) -> None:
        self.received += 1
        if self.tap.active:
            self.tap.publish("midi", lambda: self._describe(msg))
        with self._lock:
            self.mapper.handle(msg)

    def _describe(self, msg: mido.Message) -> str:
        """``note_on channel=1 note=60 velocity=100  (port NAME)``, MIDI channels counted from 1."""
        text = str(msg)
        if hasattr(msg, "channel"):
            text = text.replace(f"channel={msg.channel}", f"channel={msg.channel + 1}", 1)
        where = VIRTUAL_PORT_NAME if self.virtual else (self._port_name or str(self.port_spec))
        return f"{text}  (port {where})"

    def _list_names(self) -> list[str]:
        # While open, list through the port's own client: mido.get_input_names would
        # create (and drop) a backend client, e.g. a JACK client, every check.
        port = self._port
        if isinstance(port, RtMidiInput):
            return port.port_names()
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
        log.warning(
            "MIDI input %r disconnected; released %d actuator channel(s); will reopen when it returns",
            self._port_name,
            len(released),
        )
        self._close_port()
