"""scripts/jack_reclaim.py frees the JACK registry slots of dead servers and nothing else."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

from tests.e2e.jackutil import reclaim_dead_jack_servers

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "jack_reclaim.py"
ENTRY = 264  # jack2 on x86_64: pid_t + 257-byte name, padded
HDR_LEN = 24 + 8 * ENTRY


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _registry(path: Path, servers: list[tuple[int, str]]) -> None:
    head = struct.pack("<IHHIIII", 0x4A41434B, 0, 0, 1, HDR_LEN + 4096, HDR_LEN, 268)
    body = b"".join(struct.pack("<i", pid) + name.encode().ljust(ENTRY - 4, b"\0") for pid, name in servers)
    body += bytes(ENTRY * (8 - len(servers)))
    path.write_bytes(head + body + b"\xab" * 4096)  # the segment entries after the header stay as they are


def _slots(path: Path) -> list[tuple[int, str]]:
    data = path.read_bytes()
    out = []
    for i in range(8):
        at = 24 + i * ENTRY
        pid = struct.unpack_from("<i", data, at)[0]
        out.append((pid, data[at + 4 : at + ENTRY].split(b"\0", 1)[0].decode()))
    return out


def test_dead_servers_are_freed_live_ones_kept(tmp_path: Path) -> None:
    dead = _dead_pid()
    registry = tmp_path / "jack-shm-registry"
    _registry(registry, [(os.getpid(), "jack-0:alive:"), (dead, "jack-0:killed:"), (0, "")])
    before = registry.read_bytes()
    out = subprocess.run([sys.executable, str(SCRIPT), str(registry)], capture_output=True, text=True, check=True)
    assert f"jack-0:killed: (pid {dead})" in out.stdout
    slots = _slots(registry)
    assert slots[0] == (os.getpid(), "jack-0:alive:")
    assert slots[1] == (0, "")
    assert all(slot == (0, "") for slot in slots[2:])
    after = registry.read_bytes()
    assert after[HDR_LEN:] == before[HDR_LEN:] and after[:24] == before[:24]
    # a second run has nothing to free
    again = subprocess.run([sys.executable, str(SCRIPT), str(registry)], capture_output=True, text=True, check=True)
    assert again.stdout == ""


def test_a_file_of_another_layout_is_left_alone(tmp_path: Path) -> None:
    other = tmp_path / "jack-shm-registry"
    content = b"not a jack registry" * 200
    other.write_bytes(content)
    subprocess.run([sys.executable, str(SCRIPT), str(other)], check=True)
    assert other.read_bytes() == content
    assert subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "missing")], check=True).returncode == 0


def test_the_helper_frees_the_machine_registry_only_of_dead_servers() -> None:
    # on this machine: whatever it frees belongs to servers that are gone
    for freed in reclaim_dead_jack_servers():
        pid = int(freed.rsplit("pid ", 1)[1].rstrip(")"))
        assert not Path(f"/proc/{pid}").exists()
