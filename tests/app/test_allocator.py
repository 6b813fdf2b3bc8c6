"""serve's allocator tuning: on glibc, a process' threads share two malloc arenas."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

from vibsynth.app.allocator import ARENA_MAX, tune_allocator

glibc_only = pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's"
)

#: Eight threads allocate and keep blocks above pymalloc's 512 bytes (they come from malloc), then
#: glibc's malloc_stats() lists the arenas on stderr.
PROGRAM = """
import ctypes, sys, threading
from vibsynth.app.allocator import tune_allocator
if sys.argv[1] == "tuned":
    print("set", sorted(tune_allocator()), flush=True)
kept, ready = [], threading.Barrier(8)
def work():
    ready.wait()  # all eight at once: each needs an arena while the others hold theirs
    kept.append([bytes(4096 + i) for i in range(200)])
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads: t.start()
for t in threads: t.join()
ctypes.CDLL(None).malloc_stats()
"""


def arenas(mode: str, env: dict[str, str] | None = None) -> tuple[int, str]:
    done = subprocess.run([sys.executable, "-c", PROGRAM, mode], capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode == 0, done.stderr
    return done.stderr.count("Arena "), done.stdout


@glibc_only
def test_tuned_threads_share_two_arenas_where_untuned_ones_take_one_each():
    untuned, _ = arenas("untuned")
    tuned, said = arenas("tuned")
    print(f"malloc arenas after eight threads allocated: {untuned} untuned, {tuned} tuned")
    assert untuned > ARENA_MAX  # the test can tell
    assert tuned <= ARENA_MAX
    assert "MALLOC_ARENA_MAX" in said and "MALLOC_MMAP_THRESHOLD_" in said


@glibc_only
def test_a_users_own_glibc_setting_is_left_alone():
    import os

    env = dict(os.environ, MALLOC_ARENA_MAX="6")
    count, said = arenas("tuned", env)
    assert "MALLOC_ARENA_MAX" not in said and "MALLOC_MMAP_THRESHOLD_" in said
    assert ARENA_MAX < count <= 6


def test_elsewhere_it_does_nothing(monkeypatch):
    monkeypatch.setattr(platform, "libc_ver", lambda: ("", ""))
    assert tune_allocator() == {}
