"""Free the slots of dead JACK servers in JACK's shared registry (jack2, POSIX shm).

jack2 keeps at most 8 servers per machine in ``/dev/shm/jack-shm-registry``. A server that
dies without a clean shutdown (SIGKILL, a test killing "the device", an aborted run) keeps
its slot, and only a new server *of the same name* reclaims it. Tests and benchmarks give
every private server a unique name, so dead slots pile up until ``jackd`` refuses to start
("Too many servers already active"). This clears the slots whose process no longer exists,
and nothing else. Run it before starting a private server:

    python3 scripts/jack_reclaim.py        # prints what it freed

The layout read here is jack2's ``jack_shm_header_t`` (common/shm.h): a header of
``hdr_len`` bytes whose server array starts at byte 24, 8 entries of ``(hdr_len - 24) / 8``
bytes each, an entry being ``pid_t pid`` followed by the NUL-terminated server prefix. A
file that does not match that layout is left alone.
"""

from __future__ import annotations

import os
import struct
import sys

REGISTRY = "/dev/shm/jack-shm-registry"
MAGIC = 0x4A41434B  # 'JACK'
MAX_SERVERS = 8
SERVERS_AT = 24


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def reclaim(path: str = REGISTRY) -> list[str]:
    """Clear the registry entries of servers whose process is gone; the names freed."""
    try:
        fd = os.open(path, os.O_RDWR)
    except OSError:
        return []
    freed = []
    try:
        head = os.pread(fd, SERVERS_AT, 0)
        if len(head) < SERVERS_AT:
            return []
        magic, hdr_len = struct.unpack_from("<I", head, 0)[0], struct.unpack_from("<I", head, 16)[0]
        entry = (hdr_len - SERVERS_AT) // MAX_SERVERS
        if magic != MAGIC or entry < 8 or hdr_len > 1 << 16:
            return []
        for i in range(MAX_SERVERS):
            at = SERVERS_AT + i * entry
            raw = os.pread(fd, entry, at)
            pid = struct.unpack_from("<i", raw, 0)[0]
            if pid <= 0 or _alive(pid):
                continue
            name = raw[4:].split(b"\0", 1)[0].decode("utf-8", "replace")
            # the name first, then the pid: a server registering meanwhile only takes slots whose pid is 0
            os.pwrite(fd, bytes(entry - 4), at + 4)
            os.pwrite(fd, struct.pack("<i", 0), at)
            freed.append(f"{name} (pid {pid})")
    finally:
        os.close(fd)
    return freed


def main() -> int:
    for name in reclaim(sys.argv[1] if len(sys.argv) > 1 else REGISTRY):
        print(f"jack_reclaim: freed the registry slot of dead server {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
