"""PortAudio's life cycle around device loss: re-scan, abandon, shut down without hanging.

PortAudio sees new devices (a restarted JACK server) only after ``Pa_Terminate`` +
``Pa_Initialize``. After a JACK server died under it, that is not possible in the same
library instance (measured with PortAudio 19.6/19.7 and jack2 1.9.21):

* ``Pa_AbortStream``/``Pa_StopStream``/``Pa_CloseStream`` on the dead stream wait 10 min
  for a JACK process thread that will never run again;
* ``Pa_Terminate`` asserts on ``jack_deactivate``: the whole process aborts (SIGABRT).

So :class:`PortAudioRuntime` keeps a *dirty* flag. A clean instance is re-scanned with
``Pa_Terminate`` + ``Pa_Initialize``. A dirty one (its JACK server died, or a stream or a
call had to be abandoned) is never called again: a fresh copy of the PortAudio shared
library is loaded (its own globals) and sounddevice is pointed at it. The old one stays
loaded for good (unloading it makes libjack call into freed code) and costs a few hundred
KB per device loss. At exit a dirty instance is not terminated either: sounddevice's
``atexit`` hook is disarmed instead.

One runtime serves every stream of a process (:func:`shared_runtime`: the output and the
input, which on JACK share PortAudio's one JACK client). ``Pa_Terminate`` closes *every*
stream of the instance, so a re-scan is skipped while an attached stream still plays
(:meth:`PortAudioRuntime.attach`; a stream that lost its device re-opens on the instance as it
is); :attr:`PortAudioRuntime.epoch` counts the re-scans, so a stream opened before the last one
is known to be gone without calling it; :attr:`PortAudioRuntime.lock` serialises the streams'
re-scans and opens.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import threading
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from vibsynth.engine.supervisor import HungCallError, call_with_timeout
from vibsynth.errors import DeviceError

__all__ = ["PortAudioRuntime", "StreamPeer", "shared_runtime", "load_library_copy", "CALL_TIMEOUT_S"]

log = logging.getLogger(__name__)

#: The sounddevice module: this file reaches into its private library handle (``_lib``,
#: ``_initialized``) to swap PortAudio, so it is typed loosely on purpose.
SoundDevice = Any

#: Time limit of one PortAudio call (open, start, initialise) before it is abandoned.
CALL_TIMEOUT_S = 2.0
#: Time limit of stopping/closing a stream before it is abandoned.
CLOSE_TIMEOUT_S = 1.0
#: How long closing a stream waits for another stream's re-scan or open to finish.
LOCK_WAIT_S = 0.25
#: No new re-scan while this many abandoned PortAudio calls have not returned: they may
#: hold a driver-wide lock (libjack's client-open mutex), so more attempts would only pile up.
MAX_HUNG_CALLS = 2

#: Library instances and streams that must never be freed (PortAudio/JACK may still call into them).
_KEEP_ALIVE: list[Any] = []

#: PortAudio's paStreamIsStopped: stopping a stream that already stopped is fine.
PA_STREAM_IS_STOPPED = -9983

_STREAM_METHODS = {"Pa_StopStream": "stop", "Pa_AbortStream": "abort", "Pa_CloseStream": "close"}


def _stream_call(sd: SoundDevice, lib: Any, stream: Any, function: str) -> int:
    """``Pa_StopStream``/``Pa_AbortStream``/``Pa_CloseStream`` on ``stream`` through ``lib``; the error code.

    A sounddevice stream (it has ``_ptr``) is called through the library it was opened
    with, not through ``sounddevice._lib`` (which may meanwhile point to a fresh copy).
    Other stream objects (test doubles) are called by method name and return 0.
    """
    ptr = getattr(stream, "_ptr", None)
    if ptr is not None and lib is not None and hasattr(lib, function):
        code = int(getattr(lib, function)(ptr))
        if function == "Pa_CloseStream":
            stream._ptr = sd._ffi.NULL
        return code
    getattr(stream, _STREAM_METHODS[function])()
    return 0


def _loaded_library_path(sd: SoundDevice) -> str:
    """The file of the PortAudio library sounddevice loaded first (Linux: from /proc/self/maps)."""
    name = str(getattr(sd, "_libname", ""))
    if os.path.isabs(name) and os.path.exists(name):
        return name
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            for line in maps:
                path = line.rstrip("\n").split(" ")[-1]
                base = os.path.basename(path)
                if base.startswith("libportaudio") and ".so" in base and os.path.exists(path):
                    return path
    except OSError:
        pass
    raise DeviceError("cannot find the PortAudio library file to load a fresh copy (needs Linux /proc)")


def load_library_copy(sd: SoundDevice) -> Any:
    """Load a private copy of the PortAudio library (fresh global state) with sounddevice's FFI.

    The copy is unlinked right after loading (the mapping stays valid).

    Raises
    ------
    DeviceError
        No usable copy could be made or loaded (no writable, executable directory).
    """
    source = _loaded_library_path(sd)
    places = [
        tempfile.gettempdir(),
        os.environ.get("XDG_RUNTIME_DIR", ""),
        str(Path.home() / ".cache" / "vibsynth"),
        "/dev/shm",
    ]
    errors = []
    for place in filter(None, places):
        try:
            os.makedirs(place, exist_ok=True)
            fd, copy = tempfile.mkstemp(prefix="vibsynth-portaudio-", suffix=".so", dir=place)
            os.close(fd)
        except OSError as exc:
            errors.append(f"{place}: {exc.strerror or exc}")
            continue
        try:
            shutil.copyfile(source, copy)
            return sd._ffi.dlopen(copy)
        except (OSError, ImportError) as exc:  # cffi raises OSError when dlopen fails (e.g. noexec)
            errors.append(f"{place}: {exc}")
        finally:
            try:
                os.unlink(copy)
            except OSError:
                pass
    raise DeviceError(f"cannot load a fresh copy of {source}: {'; '.join(errors)}")


class _StderrMute:
    """Send fd 2 to /dev/null around ``Pa_Initialize`` (ALSA/JACK scan noise); restorable from another thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._saved: int | None = None

    def mute(self) -> None:
        with self._lock:
            if self._saved is not None:
                return
            try:
                saved = os.dup(2)
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 2)
                os.close(devnull)
            except OSError:
                return
            self._saved = saved

    def restore(self) -> None:
        with self._lock:
            saved, self._saved = self._saved, None
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)


class StreamPeer(Protocol):
    """A stream attached to a runtime (:class:`~vibsynth.engine.pa_stream.PortAudioStream`)."""

    def stream_alive(self) -> bool:
        """True while it holds a healthy stream (called under the runtime's lock)."""


class PortAudioRuntime:
    """One sounddevice module's PortAudio instance, re-scannable after device loss.

    Parameters
    ----------
    sd : module
        python-sounddevice (or a test double with ``_lib``, ``_initialized``,
        ``_terminate``, ``_check``, ``_ffi`` and ``query_hostapis``).
    fresh_library : callable, optional
        ``fresh_library(sd) -> lib`` loads a new library instance (default
        :func:`load_library_copy`).
    call_timeout_s, close_timeout_s : float

    Attributes
    ----------
    dirty : str
        Why this instance must never be terminated or re-used ("" = clean).
    generation : int
        Library instances loaded so far (0 = the one sounddevice loaded).
    epoch : int
        Re-scans so far (``Pa_Terminate`` or a fresh library): a stream opened in an
        earlier epoch is closed or retired and must never be called again.
    lock : threading.RLock
        Held by a stream around a re-scan and its open, so two streams never interleave them.
    """

    def __init__(
        self,
        sd: SoundDevice,
        *,
        fresh_library: Callable[[SoundDevice], Any] | None = None,
        call_timeout_s: float = CALL_TIMEOUT_S,
        close_timeout_s: float = CLOSE_TIMEOUT_S,
    ) -> None:
        self.sd = sd
        self.fresh_library = fresh_library or load_library_copy
        self.call_timeout_s = float(call_timeout_s)
        self.close_timeout_s = float(close_timeout_s)
        self.dirty = ""
        self.generation = 0
        self.epoch = 0
        self.lock = threading.RLock()
        self._peers: list[weakref.ref[StreamPeer]] = []
        self._stderr = _StderrMute()
        self._hung: list[tuple[str, threading.Event]] = []

    # -- streams sharing the instance -------------------------------------------------
    def attach(self, peer: StreamPeer) -> None:
        """Let ``peer``'s stream veto re-scans while it plays (held weakly)."""
        with self.lock:
            self._peers = [ref for ref in self._peers if ref() is not None and ref() is not peer]
            self._peers.append(weakref.ref(peer))

    def _peer_playing(self) -> bool:
        for ref in self._peers:
            peer = ref()
            try:
                if peer is not None and peer.stream_alive():
                    return True
            except Exception as exc:  # noqa: BLE001 - a broken peer must not block the others
                log.info("asking a stream whether it plays: %s", exc)
        return False

    # -- bounded calls ---------------------------------------------------------------
    def call(self, fn: Callable[[], Any], what: str, timeout_s: float | None = None) -> Any:
        """:func:`call_with_timeout`; a hung call makes the instance dirty and is remembered until it returns."""
        returned = threading.Event()

        def run() -> Any:
            try:
                return fn()
            finally:
                returned.set()

        try:
            return call_with_timeout(run, self.call_timeout_s if timeout_s is None else timeout_s, what)
        except HungCallError:
            self._hung.append((what, returned))
            self.mark_dirty(f"{what} hung")
            raise

    def hung(self) -> list[str]:
        """This runtime's abandoned calls that have not returned yet."""
        self._hung = [(what, done) for what, done in self._hung if not done.is_set()]
        return [what for what, _ in self._hung]

    def mark_dirty(self, why: str) -> None:
        """Never call this library instance again (its next re-scan loads a fresh copy)."""
        if not self.dirty:
            self.dirty = why
            log.info("PortAudio instance %d retired: %s", self.generation, why)

    # -- re-scan ----------------------------------------------------------------------
    def reinitialize(self) -> None:
        """Make PortAudio re-scan the devices (terminate + initialise, or a fresh library copy).

        Raises
        ------
        DeviceError
            PortAudio could not be initialised (or a call hung: :class:`HungCallError`).
        """
        with self.lock:
            self._reinitialize()

    def _reinitialize(self) -> None:
        sd = self.sd
        hung = self.hung()
        if len(hung) >= MAX_HUNG_CALLS:
            raise DeviceError(f"waiting for {len(hung)} hung PortAudio calls to return ({', '.join(hung)})")
        if self._peer_playing():
            # Another stream plays on this instance: a re-scan would close it. Open on the
            # instance as it is (its device list is as fresh as that stream's).
            if self.dirty:
                raise DeviceError(f"PortAudio needs a re-scan ({self.dirty}) but another stream still plays on it")
            if getattr(sd, "_initialized", 0) > 0:
                return
        if self.dirty:
            lib = self.call(lambda: self.fresh_library(sd), "loading a fresh PortAudio library")
            _KEEP_ALIVE.append(sd._lib)
            sd._lib, sd._initialized = lib, 0
            self.generation += 1
            self.epoch += 1
            self.dirty = ""
            log.info("PortAudio instance %d loaded", self.generation)
        else:
            self.terminate()
        try:
            self.call(self._initialize, "initialising PortAudio")
        except HungCallError:
            self._stderr.restore()  # the abandoned call left fd 2 on /dev/null
            raise

    def _initialize(self) -> None:
        sd = self.sd
        lib = sd._lib
        self._stderr.mute()
        try:
            code = lib.Pa_Initialize()
        finally:
            self._stderr.restore()
        try:
            sd._check(code, "Error initializing PortAudio")
        except Exception as exc:
            raise DeviceError(str(exc)) from None
        if sd._lib is lib:  # not a late return after this instance was replaced
            sd._initialized += 1

    def terminate(self) -> None:
        """``Pa_Terminate`` until uninitialised, unless dirty (then nothing: it could abort the process).

        Nothing either while an attached stream plays (``Pa_Terminate`` would close it).
        """
        with self.lock:
            self._terminate()

    def _terminate(self) -> None:
        sd = self.sd
        if self.dirty or self._peer_playing():
            return
        if getattr(sd, "_initialized", 0) > 0:
            self.epoch += 1
        while getattr(sd, "_initialized", 0) > 0:
            try:
                self.call(sd._terminate, "terminating PortAudio")
            except HungCallError:
                raise
            except Exception as exc:  # a PortAudioError: count it as terminated, do not loop
                sd._initialized = max(0, sd._initialized - 1)
                log.info("Pa_Terminate: %s", exc)

    # -- streams -----------------------------------------------------------------------
    def forget(self, stream: Any) -> None:
        """Never call ``stream`` again (a re-scan closed it, or retired its instance); keep it alive."""
        _KEEP_ALIVE.append(stream)

    def abandon(self, stream: Any, why: str) -> None:
        """Keep ``stream`` alive for good without calling it again; the instance becomes dirty."""
        _KEEP_ALIVE.append(stream)
        self.mark_dirty(why)

    def close(self, stream: Any, *, dead: bool, graceful: bool = False) -> bool:
        """Stop and close ``stream`` in bounded time. Returns True if it was closed.

        Parameters
        ----------
        dead : bool
            Its JACK server is gone: do not call PortAudio on it at all (abandon it).
        graceful : bool
            ``stop()`` (play out queued buffers) instead of ``abort()``.
        """
        if dead:
            self.abandon(stream, "its JACK server died under an open stream")
            return False
        lib = getattr(self.sd, "_lib", None)  # the stream's own library, even if a copy replaces it later

        def shut() -> bool:
            code = _stream_call(self.sd, lib, stream, "Pa_StopStream" if graceful else "Pa_AbortStream")
            if code not in (0, PA_STREAM_IS_STOPPED):
                # Never close a stream that did not stop: with its JACK server gone,
                # Pa_CloseStream asserts and aborts the process.
                log.info("stopping the audio stream failed (PortAudio error %d); abandoning it", code)
                return False
            _stream_call(self.sd, lib, stream, "Pa_CloseStream")
            return True

        # Not in the middle of another stream's re-scan or open, if it can be helped (exits are bounded).
        locked = self.lock.acquire(timeout=LOCK_WAIT_S)
        try:
            closed = self.call(shut, "closing the audio stream", self.close_timeout_s)
        except HungCallError:
            _KEEP_ALIVE.append(stream)
            return False
        except Exception as exc:  # noqa: BLE001 - a stand-in stream's error: treat as closed
            log.info("closing the audio stream: %s", exc)
            return True
        finally:
            if locked:
                self.lock.release()
        if not closed:
            self.abandon(stream, "its stream could not be stopped")
        return bool(closed)

    def shutdown(self) -> bool:
        """At process exit: terminate PortAudio if that is safe, else disarm sounddevice's exit hook.

        Returns True if PortAudio was terminated cleanly. False: it was dirty, a stream's
        re-scan or open was still under way (it holds :attr:`lock`: never waited for at exit),
        or ``Pa_Terminate`` hung; the process should then end with ``os._exit`` (libjack's
        exit-time destructors crash with a client whose server died).
        """
        if self.dirty or not self.lock.acquire(timeout=LOCK_WAIT_S):
            self.sd._initialized = 0  # its atexit handler would call Pa_Terminate: abort or hang
            return False
        try:
            self._terminate()
        except HungCallError:
            self.sd._initialized = 0
            return False
        finally:
            self.lock.release()
        return not _KEEP_ALIVE  # retired instances/streams: libjack may still hold their clients


_SHARED: dict[int, tuple[SoundDevice, PortAudioRuntime]] = {}
_SHARED_LOCK = threading.Lock()


def shared_runtime(sd: SoundDevice) -> PortAudioRuntime:
    """The one :class:`PortAudioRuntime` of ``sd`` (the sounddevice module) in this process."""
    with _SHARED_LOCK:
        entry = _SHARED.get(id(sd))
        if entry is None or entry[0] is not sd:
            entry = (sd, PortAudioRuntime(sd))
            _SHARED[id(sd)] = entry
        return entry[1]
