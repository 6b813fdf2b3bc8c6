"""Smoke test of an installed vibsynth: the same steps wherever a wheel or the app is built.

    python scripts/smoke.py                         # the vibsynth installed in this Python
    python scripts/smoke.py --app dist/vibsynth-app/vibsynth   # a PyInstaller app (no Python needed)

With no ``--app``: the three compiled extensions import (from the installed package, built for
the stable ABI where this Python supports it), then the ``vibsynth`` command of this Python is
checked. With ``--app``: that executable is checked. The checks, each in a temporary folder
with ``HOME`` and the ``XDG_*`` folders inside it:

1. ``--version`` prints ``vibsynth VERSION``;
2. ``render`` writes one second of 16-bit WAV at 48 kHz that is not silent;
3. ``serve --output null`` starts, prints its ``OSC on udp://HOST:PORT/`` line, and answers
   ``/vibsynth/ping i 42`` with ``/vibsynth/pong i 42``; then it stops on SIGTERM
   (``CTRL_BREAK`` on Windows) with status 0 and no traceback.

Standard library only (the app has no Python of its own to lend), and every step has a
timeout. Used by ``scripts/wheels.sh`` on the Linux wheel and the app, and by the release
workflow (``.github/workflows/wheels.yml``) on every system's wheel and app. Exit status 0 when
every check passes; otherwise one ``smoke: FAIL ...`` line says which.
"""

from __future__ import annotations

import argparse
import array
import importlib
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import wave
from pathlib import Path

EXTENSIONS = ("vibsynth.engine._core", "vibsynth.engine._input", "vibsynth.control.osc._fast")
TIMEOUT = 120.0  # seconds for one command (the first start of an app unpacks nothing, but a cold disk is slow)


class SmokeError(Exception):
    """A check failed (the message says which and what was seen)."""


def check_extensions() -> list[str]:
    """Import the three extensions; return their file names.

    On a Python that has the stable ABI's suffix (``.abi3.so``; ``.pyd`` on Windows) an
    extension built for it must be the one found: a version-specific build would mean the
    wheel is not the abi3 one.
    """
    files = []
    for name in EXTENSIONS:
        module = importlib.import_module(name)
        path = Path(module.__file__ or "")
        if sys.platform != "win32" and not path.name.endswith(".abi3.so"):
            raise SmokeError(f"{name} is not built for the stable ABI: {path.name}")
        if sys.platform == "win32" and path.name != name.rsplit(".", 1)[1] + ".pyd":
            raise SmokeError(f"{name} is not built for the stable ABI: {path.name}")
        files.append(path.name)
    return files


def osc_message(address: str, *ints: int) -> bytes:
    """An OSC message with int32 arguments (the little the smoke test sends)."""

    def padded(text: str) -> bytes:
        raw = text.encode() + b"\0"
        return raw + b"\0" * (-len(raw) % 4)

    return padded(address) + padded("," + "i" * len(ints)) + b"".join(struct.pack(">i", v) for v in ints)


def _env(folder: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIBSYNTH_", "PYTHONPATH"))}
    for key in ("HOME", "USERPROFILE", "APPDATA", "LOCALAPPDATA"):
        env[key] = str(folder / "home")
    for key in ("XDG_CONFIG_HOME", "XDG_DATA_HOME", "XDG_CACHE_HOME", "XDG_STATE_HOME"):
        env[key] = str(folder / key.lower())
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _run(command: list[str], folder: Path, *args: str) -> str:
    done = subprocess.run(
        [*command, *args], cwd=folder, env=_env(folder), capture_output=True, text=True, timeout=TIMEOUT
    )
    text = done.stdout + done.stderr
    if done.returncode != 0 or "Traceback" in text:
        raise SmokeError(f"vibsynth {' '.join(args)} exited {done.returncode}:\n{text}")
    return text


def check_version(command: list[str], folder: Path) -> str:
    text = _run(command, folder, "--version").strip()
    if not re.fullmatch(r"vibsynth \d+\.\d+\S*", text):
        raise SmokeError(f"--version printed {text!r}")
    return text


def check_render(command: list[str], folder: Path) -> float:
    """Render one second; return its RMS (full scale 1)."""
    args = ("--balance", "0.5", "--intensity", "0.6", "--seconds", "1", "--format", "pcm16", "-q")
    _run(command, folder, "render", *args, "-o", "smoke.wav")
    with wave.open(str(folder / "smoke.wav")) as wav:
        if (wav.getframerate(), wav.getsampwidth(), wav.getnframes()) != (48000, 2, 48000):
            raise SmokeError(f"smoke.wav: {wav.getframerate()} Hz, {wav.getsampwidth()} bytes, {wav.getnframes()}")
        samples = array.array("h", wav.readframes(wav.getnframes()))
    if sys.byteorder == "big":
        samples.byteswap()
    rms = (sum(v * v for v in samples) / len(samples)) ** 0.5 / 32768
    if not 1e-4 < rms < 0.9:
        raise SmokeError(f"the rendered second is silent or clipped (RMS {rms:.2e})")
    return rms


def check_serve(command: list[str], folder: Path) -> str:
    """Serve on the null output; /ping answered; a clean stop."""
    log = folder / "serve.log"
    windows = sys.platform == "win32"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [*command, "serve", "--output", "null", "--osc-port", "0", "--oscquery-port", "0", "--no-studio"],
            cwd=folder,
            env=_env(folder),
            stdout=out,
            stderr=subprocess.STDOUT,
            creationflags=subprocess.CREATE_NEW_PROCESS_GROUP if windows else 0,  # type: ignore[attr-defined]
        )
    try:
        deadline = time.monotonic() + TIMEOUT
        while not (found := re.search(r"OSC on udp://([\d.]+):(\d+)(/[^\s,]*)", log.read_text())):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise SmokeError(f"serve printed no OSC line (exit {proc.poll()}):\n{log.read_text()}")
            time.sleep(0.05)
        host, port, prefix = found.group(1), int(found.group(2)), found.group(3).rstrip("/")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.settimeout(10)
            sock.sendto(osc_message(f"{prefix}/ping", 42), (host, port))
            reply, _ = sock.recvfrom(65536)
        if reply != osc_message(f"{prefix}/pong", 42):
            raise SmokeError(f"/ping answered {reply!r}")
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.CTRL_BREAK_EVENT if windows else signal.SIGTERM)  # type: ignore[attr-defined]
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    text = log.read_text()
    if "Traceback" in text or (proc.returncode != 0 and not windows):
        raise SmokeError(f"serve ended with {proc.returncode}:\n{text}")
    return f"{prefix}/pong i 42 from {host}:{port}"


def _vibsynth_of_this_python() -> list[str]:
    scripts = Path(sys.executable).parent
    for name in ("vibsynth", "vibsynth.exe"):
        if (scripts / name).is_file():
            return [str(scripts / name)]
    found = shutil.which("vibsynth")
    return [found] if found else [sys.executable, "-m", "vibsynth"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--app", type=Path, help="check this executable (a PyInstaller app) instead")
    args = parser.parse_args(argv)
    try:
        if args.app is None:
            print("smoke: extensions " + ", ".join(check_extensions()), flush=True)
            command = _vibsynth_of_this_python()
        else:
            if not args.app.is_file():
                raise SmokeError(f"no executable {args.app}")
            command = [str(args.app.resolve())]
        with tempfile.TemporaryDirectory(prefix="vibsynth-smoke-") as tmp:
            folder = Path(tmp)
            print(f"smoke: {check_version(command, folder)}", flush=True)
            print(f"smoke: render 1 s, RMS {check_render(command, folder):.3f}", flush=True)
            print(f"smoke: serve --output null answered {check_serve(command, folder)}", flush=True)
    except (SmokeError, OSError, subprocess.TimeoutExpired) as e:
        print(f"smoke: FAIL {e}", file=sys.stderr)
        return 1
    print("smoke: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
