"""Build the compiled parts; everything else is in pyproject.toml.

* ``vibsynth.engine._core``: the real-time core (callback, mix, command ring, scheduler).
* ``vibsynth.engine._input``: the real-time input ring and its PortAudio callback.
* ``vibsynth.control.osc._fast``: the OSC UDP receive loop and its fast path.

The three are built against the limited API (``Py_LIMITED_API`` 0x030B0000) and the wheel is
tagged ``cp311-abi3``: one wheel per system serves CPython 3.11 and every later version.
``VIBSYNTH_LIMITED_API=0`` builds them against the whole C API instead (a version-specific
build: benchmarks/bench_limited_api.py compares the two). scripts/crossbuild.py reads this
file's extensions and ``GCC_FLAGS`` for the Windows and macOS cross-builds.
"""

import os
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

LIMITED_API = os.environ.get("VIBSYNTH_LIMITED_API", "1") != "0"
# The C kernel's float arithmetic exactly as written (no fused multiply-add), for gcc and clang.
GCC_FLAGS = ["-O2", "-ffp-contract=off", "-fno-strict-aliasing", "-Wall", "-Wno-unused-parameter"]


class BuildExt(build_ext):
    """Keep the C kernel's float arithmetic exactly as written (no fused multiply-add)."""

    def build_extensions(self) -> None:
        flags = ["/O2", "/fp:precise"] if self.compiler.compiler_type == "msvc" else GCC_FLAGS
        for ext in self.extensions:
            ext.extra_compile_args = flags
        super().build_extensions()

    def run(self) -> None:
        super().run()
        if not self.inplace:
            return
        for ext in self.extensions:  # an import prefers a stale _core.cpython-311-....so to the new _core.abi3.so
            built = Path(self.get_ext_fullpath(ext.name))
            for other in built.parent.glob(ext.name.rsplit(".", 1)[1] + ".*"):
                if other.suffix in (".so", ".pyd") and other != built:
                    other.unlink()


def extension(name: str, sources: list[str], **kw) -> Extension:
    if not LIMITED_API:
        return Extension(name, sources, **kw)
    return Extension(name, sources, py_limited_api=True, define_macros=[("Py_LIMITED_API", "0x030B0000")], **kw)


setup(
    ext_modules=[
        extension(
            "vibsynth.engine._core",
            ["vibsynth/engine/_core.c"],
            depends=["vibsynth/engine/_core_api.h", "vibsynth/engine/_rt.h"],
        ),
        extension("vibsynth.engine._input", ["vibsynth/engine/_input.c"], depends=["vibsynth/engine/_rt.h"]),
        extension(
            "vibsynth.control.osc._fast",
            ["vibsynth/control/osc/_fast.c"],
            depends=["vibsynth/engine/_core_api.h", "vibsynth/engine/_rt.h"],
            libraries=["ws2_32"] if sys.platform == "win32" else [],
        ),
    ],
    cmdclass={"build_ext": BuildExt},
    options={"bdist_wheel": {"py_limited_api": "cp311"}} if LIMITED_API else {},
)
