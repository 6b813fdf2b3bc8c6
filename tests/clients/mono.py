"""Compile and run C# with mono for the C# client's tests (clients/csharp/).

``mcs`` and ``mono`` come from Debian's mono-mcs and mono-runtime (``scripts/setup.sh --test``).
When they are missing the tests skip with the reason, or fail under ``VIBSYNTH_E2E_REQUIRED=1``
(CI), like the other tests that need system tools.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CLIENT = ROOT / "clients" / "csharp" / "VibsynthClient.cs"
UNITY_EXAMPLE = ROOT / "clients" / "csharp" / "Unity" / "VibsynthContactSource.cs"
HERE = Path(__file__).resolve().parent / "csharp"
CHECK = HERE / "ClientCheck.cs"
CHECK_MAIN = HERE / "CheckMain.cs"
UNITY_SHIM = HERE / "UnityEngineShim.cs"
UNITY_CHECK = HERE / "UnityCheck.cs"

# C# 6 is what mono's mcs implements fully; Unity and dotnet compile it too, so a client that
# compiles here with warnings as errors compiles there.
MCS_FLAGS = ("-langversion:6", "-warn:4", "-warnaserror", "-nologo")


def require_mono() -> None:
    """Skip (or fail under VIBSYNTH_E2E_REQUIRED=1) when mcs or mono is missing."""
    missing = [tool for tool in ("mcs", "mono") if shutil.which(tool) is None]
    if not missing:
        return
    reason = f"{' and '.join(missing)} not found (Debian packages mono-mcs, mono-runtime; scripts/setup.sh --test)"
    if os.environ.get("VIBSYNTH_E2E_REQUIRED") == "1":
        pytest.fail(f"VIBSYNTH_E2E_REQUIRED=1 but {reason}")
    pytest.skip(reason)


def compile_cs(out: Path, *sources: Path, library: bool = False, references: tuple[Path, ...] = ()) -> Path:
    """Compile ``sources`` with mcs into ``out`` (an .exe, or a .dll when ``library``).

    Raises
    ------
    AssertionError
        With mcs's output, when it fails (warnings are errors).
    """
    cmd = ["mcs", *MCS_FLAGS, f"-target:{'library' if library else 'exe'}", f"-out:{out}"]
    cmd += [f"-r:{ref}" for ref in references]
    cmd += [str(s) for s in sources]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        raise AssertionError(f"mcs failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    return out


def run_mono(exe: Path, *args: object, timeout: float = 120.0, check: bool = True) -> dict[str, str]:
    """Run a compiled program; return its ``key=value`` lines as a dict (AssertionError when it fails)."""
    done = subprocess.run(
        ["mono", "--debug", str(exe), *(str(a) for a in args)], capture_output=True, text=True, timeout=timeout
    )
    if check and done.returncode != 0:
        command = " ".join([exe.name, *map(str, args)])
        raise AssertionError(f"{command} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    found: dict[str, str] = {}
    for line in done.stdout.splitlines():
        key, sep, value = line.partition("=")
        if sep:
            found[key] = value
    return found


def build_client_check(folder: Path) -> Path:
    """``ClientCheck.exe`` (the client and the test program) compiled into ``folder``; skips without mono."""
    require_mono()
    return compile_cs(folder / "ClientCheck.exe", CLIENT, CHECK, CHECK_MAIN)


def build_unity_check(folder: Path) -> Path:
    """``UnityCheck.exe`` (the client, the Unity example, the UnityEngine shim, the test program) in ``folder``."""
    require_mono()
    return compile_cs(folder / "UnityCheck.exe", CLIENT, UNITY_EXAMPLE, UNITY_SHIM, UNITY_CHECK, CHECK_MAIN)
