"""One running object per controller (a clip player, a sources' mixer, a follower), found by the adapters.

A :class:`Registry` maps a controller to the object serving it while that object runs, without
keeping either alive (weak keys), so an OSC table or the studio can find ``follower_of(controller)``
without being handed it.
"""

from __future__ import annotations

import threading
import weakref
from typing import Any, Generic, TypeVar

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(Generic[T]):
    """Controller -> the running object of one kind (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: weakref.WeakKeyDictionary[Any, T] = weakref.WeakKeyDictionary()

    def attach(self, controller: Any, item: T) -> None:
        """Make ``item`` the one of ``controller`` (what :meth:`of` returns)."""
        with self._lock:
            self._items[controller] = item

    def detach(self, controller: Any, item: T) -> None:
        """Forget ``item`` (if it is still the controller's)."""
        with self._lock:
            if self._items.get(controller) is item:
                del self._items[controller]

    def of(self, controller: Any) -> T | None:
        """The running object of ``controller``, or None."""
        with self._lock:
            return self._items.get(controller)
