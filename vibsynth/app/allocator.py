"""The C allocator of a long-running serve: memory that follows what is in use, not its high water.

glibc's malloc gives each thread that allocates its own arena (up to 8 per core) and, after a large
block is freed, raises its mmap threshold so that later large blocks come from an arena instead of
their own mapping. In a service with ~25 threads whose Python work comes in bursts (OSC floods,
preset reloads, clips, Follow analysis), both leave freed pages resident in arenas: the RSS creeps
up each time a burst is bigger than any before, a high water mark reached ever more rarely. Two
arenas (Python threads allocate under the GIL: they hardly contend) and a fixed 128 KiB mmap
threshold (a large block is mapped and unmapped on its own; freed space at an arena's top goes back
above 128 KiB) keep the RSS at what is in use.

Only glibc has these knobs (``mallopt``); elsewhere (macOS, Windows, musl) this does nothing. A knob
the user set through glibc's own environment (``MALLOC_ARENA_MAX``, ``GLIBC_TUNABLES``...) is left alone.
"""

from __future__ import annotations

import ctypes
import os
import platform
import sys

__all__ = ["tune_allocator", "ARENA_MAX", "MMAP_THRESHOLD"]

#: malloc arenas of the whole process.
ARENA_MAX = 2
#: Blocks of at least this many bytes get their own mapping (fixed: glibc's dynamic raise is off).
MMAP_THRESHOLD = 128 * 1024

# mallopt parameters (glibc malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8


def tune_allocator() -> dict[str, int]:
    """Set glibc's arena count and mmap/trim thresholds for a long run; call before threads start.

    Returns
    -------
    dict
        The parameters set (name: value); empty where the C library is not glibc.
    """
    if not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc":
        return {}
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return {}
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    done: dict[str, int] = {}
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    for env, tunable, param, value in (
        ("MALLOC_ARENA_MAX", "glibc.malloc.arena_max", _M_ARENA_MAX, ARENA_MAX),
        ("MALLOC_MMAP_THRESHOLD_", "glibc.malloc.mmap_threshold", _M_MMAP_THRESHOLD, MMAP_THRESHOLD),
        ("MALLOC_TRIM_THRESHOLD_", "glibc.malloc.trim_threshold", _M_TRIM_THRESHOLD, MMAP_THRESHOLD),
    ):
        if env not in os.environ and tunable not in tunables and mallopt(param, value) == 1:
            done[env] = value
    return done
