"""Build the compiled parts; everything else is in pyproject.toml.

* ``vibsynth.engine._core``: the real-time core (callback, mix, command ring, scheduler).
* ``vibsynth.engine._input``: the real-time input ring and its PortAudio callback.
* ``vibsynth.control.osc._fast``: the OSC UDP receive loop and its fast path.
"""

import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildExt(build_ext):
    """Keep the C kernel's float arithmetic exactly as written (no fused multiply-add)."""

    def build_extensions(self) -> None:
        if self.compiler.compiler_type == "msvc":
            flags = ["/O2", "/fp:precise"]
        else:
            flags = ["-O2", "-ffp-contract=off", "-fno-strict-aliasing", "-Wall", "-Wno-unused-parameter"]
        for ext in self.extensions:
            ext.extra_compile_args = flags
        super().build_extensions()


setup(
    ext_modules=[
        Extension(
            "vibsynth.engine._core",
            ["vibsynth/engine/_core.c"],
            depends=["vibsynth/engine/_core_api.h", "vibsynth/engine/_rt.h"],
        ),
        Extension("vibsynth.engine._input", ["vibsynth/engine/_input.c"], depends=["vibsynth/engine/_rt.h"]),
        Extension(
            "vibsynth.control.osc._fast",
            ["vibsynth/control/osc/_fast.c"],
            depends=["vibsynth/engine/_core_api.h"],
            libraries=["ws2_32"] if sys.platform == "win32" else [],
        ),
    ],
    cmdclass={"build_ext": BuildExt},
)
