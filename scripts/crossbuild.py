"""Cross-build vibsynth's wheels for Windows and macOS on Linux, and check what was built (issue 32).

    python scripts/crossbuild.py windows macos-arm64 macos-x86_64 --out dist [--sdist dist/vibsynth-X.tar.gz]
    python scripts/crossbuild.py windows --update-def     # rewrite scripts/cross/win/python3.def

The three C extensions are compiled against the limited API (``Py_LIMITED_API``, as setup.py
asks) with this machine's CPython headers, which are the same on every system but for
``pyconfig.h``: ``scripts/cross/<system>/pyconfig.h`` stands in for it (a staged include folder
has every header of this Python but its own ``pyconfig.h``, as ``#include "pyconfig.h"`` in
Python.h would otherwise find that one first).

* **windows** (``win_amd64``): Debian's mingw-w64 (``x86_64-w64-mingw32-gcc``). The extensions
  link against ``python3.dll``, the stable ABI's DLL, through an import library that
  ``x86_64-w64-mingw32-dlltool`` makes from ``scripts/cross/win/python3.def``; that file lists
  exactly the symbols the objects import (``nm -u``: ``__imp_*``), checked on every build
  (``--update-def`` rewrites it). libgcc is linked statically, so each ``.pyd`` needs
  ``python3.dll`` and Windows' own DLLs only.
* **macos-arm64** (``macosx_11_0_arm64``), **macos-x86_64** (``macosx_10_9_x86_64``): ``zig cc``
  from the ziglang package, ``-undefined dynamic_lookup`` as CPython's own builds link
  extensions (the interpreter provides the API; no libpython).

Each binary is then checked: a Windows ``.pyd`` is a PE32+ x86-64 DLL exporting only
``PyInit_<name>`` and importing ``python3.dll`` (never ``python3X.dll``) and system DLLs only
(``objdump -p``); a macOS ``.so`` is a thin Mach-O of its architecture, its minimum macOS that of
the wheel's tag, exporting only ``_PyInit_<name>``, loading ``/usr/lib/libSystem.B.dylib`` only,
every other symbol looked up at run time being a Python one. The wheel (``cp311-abi3-<tag>``)
holds the package as the Linux wheel does: setuptools' ``build_py`` and ``dist_info`` of the
same sources, the compiled extensions in place of Linux's.

The sources are the sdist's (``--sdist``), or else the files git tracks, copied. These wheels
prove the C compiles and links for those systems; the release wheels are built natively by
``.github/workflows/wheels.yml``.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

ROOT = Path(__file__).resolve().parents[1]
CROSS = ROOT / "scripts" / "cross"
DEF_FILE = CROSS / "win" / "python3.def"
ABI_TAG = "cp311-abi3"
# Windows system libraries each extension links (setup.py names them for a native build)
WINDOWS_LIBRARIES = {"vibsynth.control.osc._fast": ["ws2_32"]}
# What a .pyd may import: the stable ABI's DLL and Windows' own DLLs (msvcrt: mingw-w64's C library)
WINDOWS_DLLS = re.compile(r"(?i)^(python3|kernel32|msvcrt|ws2_32|advapi32|user32|api-ms-win-[a-z0-9-]+)\.dll$")
# Data, not functions, in python3.dll (the .def marks them DATA: no call thunk)
DATA_SYMBOL = re.compile(r"^(PyExc_\w+|_Py_\w+Struct|Py\w+_Type)$")


class CrossError(Exception):
    """A build step or a check failed."""


@dataclass(frozen=True)
class Target:
    name: str  # the command-line name
    system: str  # "windows" | "macos"
    platform_tag: str
    compiler: tuple[str, ...]
    suffix: str  # the extension file's suffix
    arch: str = ""  # macOS: "arm64" | "x86_64"
    minos: tuple[int, int] = (0, 0)  # macOS: the minimum version of the tag


def _zig(triple: str) -> tuple[str, ...]:
    return (sys.executable, "-m", "ziglang", "cc", "-target", triple)


TARGETS = {
    t.name: t
    for t in (
        Target("windows", "windows", "win_amd64", ("x86_64-w64-mingw32-gcc",), ".pyd"),
        Target("macos-arm64", "macos", "macosx_11_0_arm64", _zig("aarch64-macos.11.0"), ".abi3.so", "arm64", (11, 0)),
        Target("macos-x86_64", "macos", "macosx_10_9_x86_64", _zig("x86_64-macos.10.9"), ".abi3.so", "x86_64", (10, 9)),
    )
}


def run(command: list[str], *, cwd: Path | None = None, timeout: float = 600) -> str:
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise CrossError(f"{' '.join(command)} failed ({done.returncode}):\n{done.stdout}{done.stderr}")
    return done.stdout + done.stderr


# ------------------------------------------------------------------ sources and the package's pure part
def source_tree(work: Path, sdist: Path | None) -> Path:
    """The sources to build: the sdist unpacked, or the files git tracks copied."""
    if sdist is not None:
        with tarfile.open(sdist) as tar:
            tar.extractall(work / "sdist", filter="data")
        (src,) = (work / "sdist").iterdir()
        return src
    src = work / "src"
    listed = run(["git", "ls-files", "-z"], cwd=ROOT).split("\0")
    for name in listed:
        if name and (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    return src


@dataclass(frozen=True)
class Extension:
    name: str  # vibsynth.engine._core
    sources: tuple[str, ...]
    macros: tuple[tuple[str, str | None], ...]


def read_setup(src: Path) -> tuple[list[Extension], list[str]]:
    """setup.py's extensions and compiler flags (run with ``setup()`` captured)."""
    setup_py = src / "setup.py"
    captured: dict = {}
    namespace = {"__file__": str(setup_py), "__name__": "vibsynth_setup"}
    with mock.patch("setuptools.setup", lambda **kw: captured.update(kw)):
        exec(compile(setup_py.read_text(), str(setup_py), "exec"), namespace)
    extensions = [
        Extension(e.name, tuple(e.sources), tuple((k, v) for k, v in e.define_macros)) for e in captured["ext_modules"]
    ]
    limited = [e.name for e in extensions if "Py_LIMITED_API" not in dict(e.macros)]
    if limited:
        raise CrossError(f"setup.py builds {limited} without Py_LIMITED_API: no abi3 wheel can hold them")
    return extensions, list(namespace["GCC_FLAGS"])


def pure_part(src: Path, work: Path) -> tuple[Path, Path]:
    """The package as the wheel holds it (modules, stubs, data) and its .dist-info (setuptools)."""
    lib, meta = work / "lib", work / "meta"
    meta.mkdir(parents=True, exist_ok=True)
    run([sys.executable, "setup.py", "-q", "build_py", "--build-lib", str(lib)], cwd=src)
    run([sys.executable, "setup.py", "-q", "dist_info", "--output-dir", str(meta)], cwd=src)
    (info,) = meta.glob("*.dist-info")
    return lib, info


# ------------------------------------------------------------------ compiling and linking
def staged_include(work: Path, system: str) -> Path:
    """This Python's headers with scripts/cross/<system>/pyconfig.h in place of its own."""
    folder = work / f"include-{system}"
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    headers = Path(sysconfig.get_paths()["include"])
    for item in headers.iterdir():
        if item.name != "pyconfig.h":
            (folder / item.name).symlink_to(item)
    shutil.copy2(CROSS / ("win" if system == "windows" else "macos") / "pyconfig.h", folder / "pyconfig.h")
    return folder


def compile_objects(
    target: Target, ext: Extension, src: Path, include: Path, flags: list[str], out: Path
) -> list[Path]:
    objects = []
    macros = [f"-D{k}" if v is None else f"-D{k}={v}" for k, v in ext.macros]
    for source in ext.sources:
        obj = out / f"{ext.name}.{Path(source).stem}.o"
        text = run(
            [*target.compiler, *flags, "-DNDEBUG", "-fwrapv", *macros, f"-I{include}", "-c", source, "-o", str(obj)],
            cwd=src,
        )
        if "warning:" in text:
            raise CrossError(f"{target.name}: {source} compiles with warnings:\n{text}")
        objects.append(obj)
    return objects


def windows_imports(objects: list[Path]) -> set[str]:
    """The python3.dll symbols the objects use: ``__imp_X`` (a dllimport call or datum) or ``X``
    (a function's address in a static initializer, e.g. ``Py_tp_new``: the import library's thunk)."""
    names = set()
    for line in run(["x86_64-w64-mingw32-nm", "-u", *map(str, objects)]).splitlines():
        found = re.fullmatch(r"\s*U (?:__imp_)?(_?Py\w+)", line)
        if found:
            names.add(found.group(1))
    return names


def def_text(symbols: set[str]) -> str:
    lines = [
        "; python3.dll: the stable ABI's symbols that vibsynth's extensions import, and nothing else.",
        "; Written by `python scripts/crossbuild.py windows --update-def` from `x86_64-w64-mingw32-nm -u`",
        "; of the objects; every Windows cross-build checks it still matches them. dlltool makes the",
        "; import library libpython3.a of it.",
        "LIBRARY python3.dll",
        "EXPORTS",
    ]
    lines += [f"    {name} DATA" if DATA_SYMBOL.match(name) else f"    {name}" for name in sorted(symbols)]
    return "\n".join(lines) + "\n"


def def_symbols(text: str) -> set[str]:
    body = text.split("EXPORTS", 1)[1]
    return {line.split()[0] for line in body.splitlines() if line.strip() and not line.strip().startswith(";")}


def link(target: Target, ext: Extension, objects: list[Path], work: Path, out: Path) -> Path:
    binary = out / (ext.name.rsplit(".", 1)[1] + target.suffix)
    if target.system == "windows":
        libraries = [f"-l{lib}" for lib in WINDOWS_LIBRARIES.get(ext.name, [])]
        command = [*target.compiler, "-shared", "-static-libgcc", "-s", "-Wl,--no-insert-timestamp"]
        run([*command, "-o", str(binary), *map(str, objects), f"-L{work}", "-lpython3", *libraries])
    else:
        run([*target.compiler, "-shared", "-undefined", "dynamic_lookup", "-o", str(binary), *map(str, objects)])
    return binary


# ------------------------------------------------------------------ checks of the binaries
def check_pe(binary: Path, module: str) -> dict:
    """A PE32+ x86-64 DLL exporting PyInit_<module> only, importing python3.dll and system DLLs only."""
    dump = run(["x86_64-w64-mingw32-objdump", "-p", str(binary)])
    if "file format pei-x86-64" not in dump or not re.search(r"^Magic\s+020b\s", dump, re.M):
        raise CrossError(f"{binary.name} is not a PE32+ x86-64 image")
    if not re.search(r"^Characteristics .*\n(\s+.*\n)*?\s+DLL\b", dump, re.M):
        raise CrossError(f"{binary.name} is not a DLL")
    exports_part = dump.split("[Ordinal/Name Pointer] Table", 1)
    exports = set(re.findall(r"^\s+\[\s*\d+\]\s+(\S+)$", exports_part[1], re.M)) if len(exports_part) == 2 else set()
    if exports != {f"PyInit_{module}"}:
        raise CrossError(f"{binary.name} exports {sorted(exports)}, not PyInit_{module} alone")
    dlls = re.findall(r"^\s+DLL Name: (\S+)$", dump, re.M)
    if "python3.dll" not in dlls:
        raise CrossError(f"{binary.name} does not import python3.dll: {dlls}")
    foreign = [d for d in dlls if not WINDOWS_DLLS.match(d)]
    if foreign:
        raise CrossError(f"{binary.name} imports {foreign}: neither python3.dll nor a system DLL")
    return {"exports": sorted(exports), "dlls": dlls}


def check_macho(binary: Path, module: str, target: Target) -> dict:
    """A thin Mach-O of the target's arch and minimum macOS, exporting _PyInit_<module>, no libpython."""
    from macholib import mach_o
    from macholib.MachO import MachO
    from macholib.SymbolTable import SymbolTable

    macho = MachO(str(binary))
    if len(macho.headers) != 1:
        raise CrossError(f"{binary.name} is a fat file; one architecture per wheel")
    (header,) = macho.headers
    arch = {"ARM64": "arm64", "x86_64": "x86_64"}.get(mach_o.CPU_TYPE_NAMES.get(header.header.cputype, ""))
    if arch != target.arch:
        raise CrossError(f"{binary.name} is for {arch}, not {target.arch}")
    if header.header.filetype not in (mach_o.MH_DYLIB, mach_o.MH_BUNDLE):
        raise CrossError(f"{binary.name} is neither a dylib nor a bundle")
    dylibs, minos = [], None
    for command, body, data in header.commands:
        if command.cmd in (mach_o.LC_LOAD_DYLIB, mach_o.LC_LOAD_WEAK_DYLIB, mach_o.LC_REEXPORT_DYLIB):
            dylibs.append(data.rstrip(b"\0").decode())
        elif command.cmd == mach_o.LC_BUILD_VERSION:
            minos = body.minos
        elif command.cmd == mach_o.LC_VERSION_MIN_MACOSX:
            minos = body.version
    if dylibs != ["/usr/lib/libSystem.B.dylib"]:
        raise CrossError(f"{binary.name} loads {dylibs}; only libSystem (and never a libpython) is expected")
    if minos is None or (minos >> 16, (minos >> 8) & 0xFF) != target.minos:
        raise CrossError(
            f"{binary.name}: minimum macOS {minos and (minos >> 16, (minos >> 8) & 0xFF)}, tag {target.minos}"
        )
    table = SymbolTable(macho, header)
    linker_made = re.compile(r"^(___dso_handle|__mh_\w+_header)$")  # every dylib has them
    exports = {name.decode() for _, name in table.extdefsyms}
    exports = {name for name in exports if not linker_made.match(name)}
    if exports != {f"_PyInit_{module}"}:
        raise CrossError(f"{binary.name} exports {sorted(exports)}, not _PyInit_{module} alone")
    python_symbols = set()
    for symbol, name in table.undefsyms:
        text = name.decode()
        ordinal = (symbol.n_desc >> 8) & 0xFF
        if ordinal in (0, 0xFE):  # not bound to libSystem (ordinal 1): found in the interpreter at run time
            if not re.fullmatch(r"_{1,2}Py\w+", text):
                raise CrossError(f"{binary.name} looks {text} up at run time: only Python's symbols may be")
            python_symbols.add(text[1:])
    return {"exports": sorted(exports), "dylibs": dylibs, "python_symbols": sorted(python_symbols)}


# ------------------------------------------------------------------ the wheel
def _record_hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def assemble_wheel(lib: Path, info: Path, binaries: dict[str, Path], target: Target, out: Path) -> Path:
    """``name-version-cp311-abi3-<tag>.whl`` of the pure part and the binaries (extension name -> file)."""
    name, version = info.name[: -len(".dist-info")].split("-", 1)
    wheel = out / f"{name}-{version}-{ABI_TAG}-{target.platform_tag}.whl"
    files: dict[str, bytes] = {}
    for path in sorted(lib.rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            files[path.relative_to(lib).as_posix()] = path.read_bytes()
    for ext_name, binary in binaries.items():
        files[ext_name.replace(".", "/") + target.suffix] = binary.read_bytes()
    dist_info = f"{name}-{version}.dist-info"
    for path in sorted(info.iterdir()):
        if path.is_file():
            files[f"{dist_info}/{path.name}"] = path.read_bytes()
    files[f"{dist_info}/WHEEL"] = (
        "Wheel-Version: 1.0\nGenerator: vibsynth scripts/crossbuild.py\nRoot-Is-Purelib: false\n"
        f"Tag: {ABI_TAG}-{target.platform_tag}\n"
    ).encode()
    record = [f"{path},{_record_hash(data)},{len(data)}" for path, data in files.items()]
    files[f"{dist_info}/RECORD"] = ("\n".join([*record, f"{dist_info}/RECORD,,"]) + "\n").encode()
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in files.items():
            zf.writestr(zipfile.ZipInfo(path, date_time=(2020, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
    return wheel


# ------------------------------------------------------------------ the whole build
def build(targets: list[Target], out: Path, work: Path, sdist: Path | None, update_def: bool) -> list[Path]:
    src = source_tree(work, sdist)
    extensions, flags = read_setup(src)
    lib, info = pure_part(src, work)
    wheels = []
    for target in targets:
        started = time.monotonic()
        objdir = work / target.name
        objdir.mkdir(parents=True, exist_ok=True)
        include = staged_include(work, target.system)
        objects = {ext.name: compile_objects(target, ext, src, include, flags, objdir) for ext in extensions}
        if target.system == "windows":
            imported = windows_imports([o for objs in objects.values() for o in objs])
            if update_def:
                DEF_FILE.write_text(def_text(imported))
            listed = def_symbols(DEF_FILE.read_text())
            if listed != imported:
                raise CrossError(
                    f"{DEF_FILE.relative_to(ROOT)} is out of date (missing {sorted(imported - listed)}, "
                    f"unused {sorted(listed - imported)}): python scripts/crossbuild.py windows --update-def"
                )
            run(["x86_64-w64-mingw32-dlltool", "-d", str(DEF_FILE), "-l", str(objdir / "libpython3.a")])
        binaries = {}
        for ext in extensions:
            binary = link(target, ext, objects[ext.name], objdir, objdir)
            module = ext.name.rsplit(".", 1)[1]
            seen = check_pe(binary, module) if target.system == "windows" else check_macho(binary, module, target)
            binaries[ext.name] = binary
            seen["python_symbols"] = len(seen.get("python_symbols", []))
            print(f"crossbuild: {target.name}: {binary.name} ok: {seen}", flush=True)
        wheel = assemble_wheel(lib, info, binaries, target, out)
        wheels.append(wheel)
        print(f"crossbuild: {wheel.name} ({wheel.stat().st_size / 1e6:.2f} MB, {time.monotonic() - started:.1f} s)")
    return wheels


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("targets", nargs="+", choices=sorted(TARGETS))
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="where the wheels go (default dist/)")
    parser.add_argument("--sdist", type=Path, help="build from this sdist (default: the files git tracks)")
    parser.add_argument("--work", type=Path, help="the build folder (default: a temporary one)")
    parser.add_argument("--update-def", action="store_true", help=f"rewrite {DEF_FILE.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    try:
        with tempfile.TemporaryDirectory(prefix="vibsynth-cross-") as tmp:
            work = args.work or Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            build([TARGETS[t] for t in args.targets], args.out.resolve(), work, args.sdist, args.update_def)
    except (CrossError, subprocess.TimeoutExpired, OSError) as e:
        print(f"crossbuild: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
