"""scripts/wheels.sh's cheap parts, the release workflow and the smoke script (issue 32 items 2-3).

In the suite: the Windows and macOS cross-builds with every binary check (scripts/crossbuild.py:
PE32+/Mach-O, exports, imports, python3.def in step) and ``abi3audit --strict`` on their wheels,
the checker refusing planted bad binaries, the smoke script on this checkout's build, and the
workflow's content. Not in the suite (minutes of pip downloads and PyInstaller): the manylinux
repair and the app, run by ``bash scripts/wheels.sh`` (docs/install.md, Numbers).
"""

from __future__ import annotations

import base64
import hashlib
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))

import crossbuild  # noqa: E402

EXTENSIONS = ("vibsynth/engine/_core", "vibsynth/engine/_input", "vibsynth/control/osc/_fast")
TAGS = {
    "windows": ("win_amd64", ".pyd"),
    "macos-arm64": ("macosx_11_0_arm64", ".abi3.so"),
    "macos-x86_64": ("macosx_10_9_x86_64", ".abi3.so"),
}


@pytest.fixture(scope="module")
def cross_wheels(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if shutil.which("x86_64-w64-mingw32-gcc") is None:
        pytest.fail("x86_64-w64-mingw32-gcc missing: scripts/setup.sh --test installs gcc-mingw-w64-x86-64-win32")
    out = tmp_path_factory.mktemp("cross")
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "crossbuild.py"), *TAGS, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=900,  # about 1 min of CPU; zig's first link per target builds its runtime (about 20 s each)
    )
    assert done.returncode == 0, done.stdout + done.stderr
    from vibsynth._version import __version__

    return {name: out / f"vibsynth-{__version__}-cp311-abi3-{tag}.whl" for name, (tag, _) in TAGS.items()}


def test_the_cross_built_wheels_hold_the_package_and_their_systems_extensions(cross_wheels):
    tracked = subprocess.run(
        ["git", "ls-files", "vibsynth"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    package = {name for name in tracked if not name.endswith((".c", ".h"))}
    for target, wheel in cross_wheels.items():
        tag, suffix = TAGS[target]
        with zipfile.ZipFile(wheel) as zf:
            names = set(zf.namelist())
            info = next(n.split("/")[0] for n in names if n.endswith(".dist-info/WHEEL"))
            assert f"Tag: cp311-abi3-{tag}" in zf.read(f"{info}/WHEEL").decode()
            assert "Root-Is-Purelib: false" in zf.read(f"{info}/WHEEL").decode()
            assert "vibsynth = vibsynth.cli:main" in zf.read(f"{info}/entry_points.txt").decode()
            metadata = zf.read(f"{info}/METADATA").decode()
            assert "Requires-Python: >=3.11" in metadata and "Requires-Dist: numpy" in metadata
            binaries = {n for n in names if n.endswith((".pyd", ".so"))}
            assert binaries == {ext + suffix for ext in EXTENSIONS}, target
            missing = package - names
            assert not missing, (target, sorted(missing))
            # RECORD: every file, with its hash and size
            rows = [line.split(",") for line in zf.read(f"{info}/RECORD").decode().splitlines()]
            recorded = {row[0]: row for row in rows}
            assert set(recorded) == names
            for name in names - {f"{info}/RECORD"}:
                data = zf.read(name)
                digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
                assert recorded[name][1:] == [f"sha256={digest}", str(len(data))], name
            if target == "windows":  # a PE32+ image: the "PE\0\0" signature, then the x86-64 machine
                data = zf.read("vibsynth/engine/_core.pyd")
                pe = int.from_bytes(data[0x3C:0x40], "little")
                assert data[:2] == b"MZ" and data[pe : pe + 6] == b"PE\0\0\x64\x86"
            else:  # a thin 64-bit Mach-O of the tag's CPU (arm64 0x0100000c, x86_64 0x01000007)
                data = zf.read("vibsynth/engine/_core.abi3.so")
                cpu = 0x0100000C if target.endswith("arm64") else 0x01000007
                assert data[:4] == b"\xcf\xfa\xed\xfe" and int.from_bytes(data[4:8], "little") == cpu


def test_abi3audit_finds_no_symbol_outside_the_stable_abi(cross_wheels):
    done = subprocess.run(
        [str(Path(sys.executable).parent / "abi3audit"), "--strict", "-s", *map(str, cross_wheels.values())],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    text = " ".join((done.stdout + done.stderr).split())
    assert text.count("3 extensions scanned; 0 ABI version mismatches and 0 ABI violations found") == 3, text


def _toy_dll(tmp_path: Path, library: str, export: str = "PyInit_toy") -> Path:
    """A DLL like an extension, importing PyLong_FromLong from ``library``."""
    (tmp_path / "toy.c").write_text(
        "__declspec(dllimport) void *PyLong_FromLong(long);\n"
        f"__declspec(dllexport) void *{export}(void) {{ return PyLong_FromLong(1); }}\n"
    )
    (tmp_path / "py.def").write_text(f"LIBRARY {library}\nEXPORTS\n    PyLong_FromLong\n")
    gcc, dlltool = "x86_64-w64-mingw32-gcc", "x86_64-w64-mingw32-dlltool"
    subprocess.run([dlltool, "-d", "py.def", "-l", "libpy.a"], cwd=tmp_path, check=True, timeout=60)
    subprocess.run([gcc, "-shared", "-o", "toy.pyd", "toy.c", "-L.", "-lpy"], cwd=tmp_path, check=True, timeout=120)
    return tmp_path / "toy.pyd"


def test_the_windows_check_refuses_a_version_specific_python_dll_or_a_stray_export(tmp_path):
    if shutil.which("x86_64-w64-mingw32-gcc") is None:
        pytest.fail("x86_64-w64-mingw32-gcc missing: scripts/setup.sh --test installs gcc-mingw-w64-x86-64-win32")
    (tmp_path / "good").mkdir()
    seen = crossbuild.check_pe(_toy_dll(tmp_path / "good", "python3.dll"), "toy")
    assert seen["exports"] == ["PyInit_toy"] and "python3.dll" in seen["dlls"]
    (tmp_path / "311").mkdir()
    with pytest.raises(crossbuild.CrossError, match=r"python311\.dll"):
        crossbuild.check_pe(_toy_dll(tmp_path / "311", "python311.dll"), "toy")
    (tmp_path / "name").mkdir()
    with pytest.raises(crossbuild.CrossError, match="PyInit_other"):
        crossbuild.check_pe(_toy_dll(tmp_path / "name", "python3.dll", export="PyInit_other"), "toy")


def test_the_def_file_lists_exactly_what_it_says(tmp_path):
    text = (ROOT / "scripts" / "cross" / "win" / "python3.def").read_text()
    symbols = crossbuild.def_symbols(text)
    assert text == crossbuild.def_text(symbols)  # as --update-def writes it
    assert {"PyType_FromSpec", "PyObject_GetBuffer", "PyCapsule_Import", "PyExc_TypeError"} <= symbols
    # none of the calls the limited API lacks at 3.11
    assert not symbols & {"PyMem_RawMalloc", "PyMem_RawCalloc", "PyMem_RawFree", "PyType_Ready"}
    assert "    PyExc_TypeError DATA" in text and "    PyType_FromSpec\n" in text


def test_the_smoke_script_passes_on_this_checkouts_build(tmp_path):
    """scripts/smoke.py as the release workflow runs it, on the abi3 extensions built in place."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "smoke.py")], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "smoke: extensions _core.abi3.so, _input.abi3.so, _fast.abi3.so"
    assert any(line.startswith("smoke: serve --output null answered /vibsynth/pong i 42") for line in lines)
    assert lines[-1] == "smoke: ok"


def test_the_smoke_script_fails_on_a_command_that_does_not_answer(tmp_path):
    fake = tmp_path / "vibsynth"
    fake.write_text("#!/bin/sh\necho vibsynth 9.9\n")
    fake.chmod(0o755)
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "smoke.py"), "--app", str(fake)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert "smoke: vibsynth 9.9" in done.stdout and "smoke: FAIL" in done.stderr


def test_the_release_workflow_builds_every_platform_and_runs_the_smoke_script():
    workflow = yaml.safe_load((ROOT / ".github" / "workflows" / "wheels.yml").read_text())
    jobs = workflow["jobs"]
    matrix = jobs["wheels"]["strategy"]["matrix"]["include"]
    platforms = {(row["os"], row["arch"]) for row in matrix}
    assert platforms == {
        ("ubuntu-latest", "x86_64"),
        ("ubuntu-24.04-arm", "aarch64"),
        ("macos-14", "arm64"),
        ("macos-13", "x86_64"),
        ("windows-latest", "AMD64"),
    }
    steps = jobs["wheels"]["steps"]
    cibw = next(s for s in steps if str(s.get("uses", "")).startswith("pypa/cibuildwheel@"))
    assert cibw["env"]["CIBW_BUILD"] == "cp311-*"  # one abi3 build per platform
    assert cibw["env"]["CIBW_TEST_COMMAND"] == "python {project}/scripts/smoke.py"
    runs = "\n".join(s.get("run", "") for s in steps)
    assert "scripts/vibsynth-app.spec" in runs and "scripts/smoke.py --app" in runs
    uploads = [s["with"]["name"] for s in steps if str(s.get("uses", "")).startswith("actions/upload-artifact@")]
    assert uploads == ["wheel-${{ matrix.name }}", "vibsynth-app-${{ matrix.name }}"]
    assert "python -m build --sdist" in jobs["sdist"]["steps"][-2]["run"]
    for path in ("scripts/smoke.py", "scripts/vibsynth-app.spec", "scripts/app/vibsynth_app.py"):
        assert (ROOT / path).is_file(), path
    spec = (ROOT / "scripts" / "vibsynth-app.spec").read_text()
    compile(spec, "vibsynth-app.spec", "exec")  # PyInstaller runs it as Python
    assert 'collect_submodules("vibsynth")' in spec and 'collect_data_files("vibsynth")' in spec
