"""One settings form: outside ``settings/`` and ``formats/`` the program passes the typed model.

The configuration is validated once, at the edge (file, environment, flags), into a
:class:`~vibsynth.settings.models_config.VibsynthConfig`; each part takes its own typed
section. The dict form (``Config.data``, ``Config.section``, ``Config.get("a.b")``) stays where
YAML is read and written and in ``vibsynth config``, which prints it with its sources. This
checks every module, lazy code included, for the old forms:

* ``settings_of`` (re-validating a config's dict) named anywhere;
* ``.data`` of a config (``config.data["audio"]``, ``load_config().data.get("osc")``);
* ``.section("<a section>")``, and ``.get("section.key")`` (a dotted config key) of a config.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

from vibsynth.settings.models_config import VibsynthConfig

PACKAGE = Path(__file__).resolve().parents[1] / "vibsynth"
#: Where the dict form lives: the loaders and formats, and the command that prints the config.
DICT_FORM_HOMES = ("settings/", "formats/", "cli/config_cmd.py")
#: Functions whose result is a ``Config``.
LOADERS = {"load_config", "config_from_args", "check_config_file"}
SECTIONS = set(VibsynthConfig.model_fields)
_DOTTED_KEY = re.compile(r"^([a-z_]+)\.[a-z_.]+$")


def _is_config(node: ast.expr) -> bool:
    """Whether an expression names a config (``config``, ``self.config``, ``cfg``, ``load_config(...)``)."""
    if isinstance(node, ast.Call):
        func = node.func
        name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        return name in LOADERS
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return name in ("config", "cfg", "conf") or name.endswith("_config")


def _problems_in(tree: ast.AST) -> list[tuple[int, str]]:
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id == "settings_of":
            found.append((node.lineno, "settings_of (validates the config again)"))
        elif isinstance(node, ast.alias) and node.name == "settings_of":
            found.append((node.lineno, "imports settings_of"))
        elif isinstance(node, ast.Attribute) and node.attr == "data" and _is_config(node.value):
            found.append((node.lineno, "reads a config's .data (the dict form)"))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args:
            first = node.args[0]
            text = first.value if isinstance(first, ast.Constant) and isinstance(first.value, str) else None
            if text is None:
                continue
            if node.func.attr == "section" and text in SECTIONS:
                found.append((node.lineno, f'.section("{text}") (the dict form)'))
            match = _DOTTED_KEY.match(text)
            if node.func.attr == "get" and match and match.group(1) in SECTIONS and _is_config(node.func.value):
                found.append((node.lineno, f'.get("{text}") (the dict form)'))
    return found


def _violations(package: Path = PACKAGE) -> list[str]:
    out = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package).as_posix()
        if rel.startswith(DICT_FORM_HOMES) or rel.startswith("data/"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        out += [f"vibsynth/{rel}:{line}: {what}" for line, what in sorted(_problems_in(tree))]
    return out


def test_outside_settings_the_program_passes_the_typed_model():
    assert _violations() == []


def test_the_checker_sees_each_old_form(tmp_path, monkeypatch):
    fake = tmp_path / "vibsynth"
    (fake / "app").mkdir(parents=True)
    (fake / "settings").mkdir()
    (fake / "app" / "bad.py").write_text(
        "from vibsynth.settings.typed import settings_of\n"
        "def f(config, other):\n"
        "    rate = config.data['audio']['rate']\n"
        "    lab = config.section('lab')\n"
        "    port = config.get('osc.port')\n"
        "    prefix = load_config().data.get('osc')\n"
        "    typed = settings_of(config)\n"
        "    fine = other.data, other.get('osc.port'), typed.knobs, other.section('x')  # a status reply...\n"
    )
    (fake / "settings" / "home.py").write_text("def g(config):\n    return config.data['audio']\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert _violations(fake) == [
        "vibsynth/app/bad.py:1: imports settings_of",
        "vibsynth/app/bad.py:3: reads a config's .data (the dict form)",
        'vibsynth/app/bad.py:4: .section("lab") (the dict form)',
        'vibsynth/app/bad.py:5: .get("osc.port") (the dict form)',
        "vibsynth/app/bad.py:6: reads a config's .data (the dict form)",
        "vibsynth/app/bad.py:7: settings_of (validates the config again)",
    ]
