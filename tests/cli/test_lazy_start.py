"""A command whose module bears its name starts with only that module: ``send`` needs no numpy."""

from __future__ import annotations

import subprocess
import sys

import pytest

from vibsynth.cli import _parser_for, build_parser

HEAVY = ("numpy", "scipy", "pydantic", "aiohttp")


def imported_after(argv: list[str]) -> set[str]:
    """The heavy packages a fresh interpreter holds after ``vibsynth <argv>`` exits."""
    code = (
        "import sys\n"
        "from vibsynth.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        f"print('HEAVY:', *(m for m in {HEAVY!r} if m in sys.modules), file=sys.stderr)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "usage: vibsynth" in done.stdout  # the help was printed
    line = [x for x in done.stderr.splitlines() if x.startswith("HEAVY:")]
    return set(line[-1].split()[1:])


@pytest.mark.parametrize("argv", [["send", "--help"], ["-v", "status", "--help"], ["monitor", "--help"]])
def test_a_client_command_imports_no_numerical_or_web_package(argv):
    assert imported_after(argv) == set()


def test_the_full_parser_still_answers_the_top_level_help():
    assert "numpy" in imported_after(["--help"])  # every command's module, as before


@pytest.mark.parametrize(
    "argv",
    [
        ["send", "/vibsynth/intensity", "0.5"],
        ["status", "--port", "9000"],
        ["-v", "render", "--balance", "0.5", "--seconds", "1", "-o", "x.wav"],
        ["clip", "list"],
    ],
)
def test_the_one_module_parser_reads_a_command_line_as_the_full_one(argv):
    one = vars(_parser_for(argv).parse_args(argv))
    full = vars(build_parser().parse_args(argv))
    assert {k: v for k, v in one.items() if k != "func"} == {k: v for k, v in full.items() if k != "func"}
    assert one["func"].__qualname__ == full["func"].__qualname__


@pytest.mark.parametrize("argv", [["config", "path"], ["encode", "--help"], ["sendd"], ["os"], ["_common"], []])
def test_a_command_with_no_module_of_its_name_gets_the_full_parser(argv):
    choices = next(a for a in _parser_for(argv)._actions if a.__class__.__name__ == "_SubParsersAction").choices
    assert {"send", "serve", "config", "render"} <= set(choices)
