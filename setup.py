"""Build the compiled real-time core (vibsynth/engine/_core.c); everything else is in pyproject.toml."""
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
    ext_modules=[Extension("vibsynth.engine._core", ["vibsynth/engine/_core.c"])],
    cmdclass={"build_ext": BuildExt},
)
