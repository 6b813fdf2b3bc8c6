"""Hot reload: a thread that polls a library (presets, clips) while the service runs (see docs/presets.md)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from vibsynth.errors import VibsynthError
from vibsynth.settings.library import POLL_READ_BYTES, POLL_READ_FILES, FileLibrary

log = logging.getLogger(__name__)


class LibraryWatcher:
    """Poll a library's folders and reload on change (edits, additions, removals).

    Parameters
    ----------
    library : FileLibrary
        A :class:`~vibsynth.settings.library.PresetLibrary`, a
        :class:`~vibsynth.settings.clips.ClipLibrary`.
    on_change : callable
        ``on_change(name)`` for every added, changed or removed item (called from the
        watcher thread; exceptions are logged, never stop the watcher). For a removed
        item ``library.get(name)`` raises: keep what is playing.
    interval_s : float
        Polling period (0.25 s: changes are picked up well within a second).

    Notes
    -----
    Everything happens in the watcher's own thread, never in the audio callback. A poll
    lists the folders and stats the ``*.yaml`` files (at most :data:`MAX_FILES_PER_FOLDER`
    each); it reads only files whose (mtime, size, inode) changed, at most
    :data:`POLL_READ_FILES` files and :data:`POLL_READ_BYTES` bytes per poll, and never a
    file over the kind's size cap (logged once). A 50 MB file in the folder costs one
    ``stat`` per poll.
    """

    def __init__(self, library: FileLibrary[Any], on_change: Callable[[str], None], interval_s: float = 0.25) -> None:
        if not (isinstance(interval_s, (int, float)) and not isinstance(interval_s, bool) and 0 < interval_s <= 10):
            raise library.kind.error(f"watch interval {interval_s!r} s is outside the allowed range (0, 10] s")
        self.library = library
        self.noun = library.kind.noun
        self.on_change = on_change
        self.interval_s = float(interval_s)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def poll(self) -> dict[str, str]:
        """Check once; read what changed (bounded, see the class notes), notify. Returns the changes."""
        changes = self.library.reload(read_files=POLL_READ_FILES, read_bytes=POLL_READ_BYTES)
        for name, kind in changes.items():
            log.info("%s %r %s", self.noun, name, kind)
            try:
                self.on_change(name)
            except VibsynthError as exc:  # e.g. a removed preset that was playing: keep what plays
                log.warning("%s %r %s: %s", self.noun, name, kind, exc)
            except Exception:  # noqa: BLE001 - a callback bug must not stop hot reload
                log.exception("%s %r: on_change callback failed", self.noun, name)
        return changes

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            try:
                self.poll()
            except Exception:  # noqa: BLE001 - keep watching whatever happens
                log.exception("%s watcher: unexpected error", self.noun)

    def start(self) -> LibraryWatcher:
        """Start the polling thread (daemon); returns self."""
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"vibsynth-{self.noun}-watcher", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> LibraryWatcher:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


#: The preset library's watcher (the service's hot reload of presets).
PresetWatcher = LibraryWatcher
