"""The strict layers stay strict: pyproject.toml's override for dsp/, engine/ and settings/ sets every
flag ``mypy --strict`` enables in the installed mypy (a new mypy may add one); the flags mypy takes
only for the whole run (``warn_redundant_casts``) are set in ``[tool.mypy]``.

``scripts/test.sh`` also runs ``mypy --strict`` on the three folders; this test says which flag the
override (what a plain ``mypy`` applies) lacks.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: mypy's own TOML reader
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
STRICT_MODULES = ["vibsynth.dsp.*", "vibsynth.engine.*", "vibsynth.settings.*"]


def strict_flags(help_text: str) -> list[str]:
    """Config names of the flags ``--strict`` enables, from ``mypy --help`` (``--extra-checks``: ``extra_checks``)."""
    match = re.search(r"--strict\s+Strict mode; enables the following flags:(.*?)\n  --", help_text, re.S)
    if match is None:
        raise AssertionError("mypy --help no longer describes --strict as a list of flags")
    listed = re.sub(r"-\s*\n\s*", "-", match.group(1))  # flags wrapped at their hyphens
    return [flag.replace("-", "_") for flag in re.findall(r"--([a-z][a-z-]*)", listed)]


def test_the_help_parser_reads_a_wrapped_list():
    text = (
        "  --strict                  Strict mode; enables the following flags:\n"
        "                            --disallow-any-generics, --disallow-subclassing-\n"
        "                            any, --extra-checks\n"
        "  --disable-error-code NAME\n"
    )
    assert strict_flags(text) == ["disallow_any_generics", "disallow_subclassing_any", "extra_checks"]


def test_the_strict_layers_set_every_flag_of_strict():
    options = pytest.importorskip("mypy.options")
    shown = subprocess.run([sys.executable, "-m", "mypy", "--help"], capture_output=True, text=True, check=True)
    flags = strict_flags(shown.stdout)
    assert {"disallow_untyped_defs", "warn_return_any", "strict_equality"} <= set(flags)  # it read the list
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    override = next(o for o in config["overrides"] if o["module"] == STRICT_MODULES)

    def per_module(flag: str) -> bool:  # no_implicit_reexport is implicit_reexport = False to mypy
        return flag in options.PER_MODULE_OPTIONS or flag.removeprefix("no_") in options.PER_MODULE_OPTIONS

    assert [flag for flag in flags if per_module(flag) and override.get(flag) is not True] == []
    assert [flag for flag in flags if not per_module(flag) and config.get(flag) is not True] == []
