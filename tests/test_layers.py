"""The package's layers: imports only go down (docs/architecture.md, "Layout").

Every ``import`` in every module is checked, including the lazy ones inside functions, so a
deferred import cannot hide a dependency that runs back up the layers.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vibsynth"

#: What each layer may import (besides itself, ``vibsynth.errors`` and the lazy package root).
ALLOWED = {
    "dsp": set(),
    "formats": {"dsp"},
    "settings": {"dsp", "formats"},
    "engine": {"dsp", "formats", "settings"},
    "research": {"dsp", "formats", "settings"},
    "control": {"dsp", "formats", "settings", "engine"},
    "app": {"dsp", "formats", "settings", "engine", "research", "control"},
    "cli": {"dsp", "formats", "settings", "engine", "research", "control", "app"},
}
#: Standard-library modules that mean file, network or process I/O: not in the pure science.
IO_MODULES = {"os", "pathlib", "io", "socket", "subprocess", "shutil", "tempfile", "gzip", "csv", "logging"}


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "data" not in p.relative_to(PACKAGE).parts)


def _layer(path: Path) -> str | None:
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else None


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
            if node.module == "vibsynth":  # from vibsynth import <subpackage>
                found += [(node.lineno, f"vibsynth.{alias.name}") for alias in node.names]
    return found


def _violations() -> list[str]:
    problems = []
    for path in _modules():
        layer = _layer(path)
        if layer is None:
            continue  # the package root and errors.py
        assert layer in ALLOWED, f"{path}: folder {layer!r} is not in the layer table (docs/architecture.md)"
        for line, module in _imports(path):
            parts = module.split(".")
            if parts[0] != "vibsynth" or len(parts) < 2 or parts[1] in ("errors", "__version__"):
                continue
            target = parts[1]
            if target != layer and target not in ALLOWED[layer] and target in ALLOWED:
                problems.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {layer} imports {module} (a layer above)")
    return problems


def test_imports_only_go_down_the_layers():
    assert _violations() == []


def test_the_checker_sees_an_upward_import(tmp_path, monkeypatch):
    fake = tmp_path / "vibsynth"
    (fake / "dsp").mkdir(parents=True)
    (fake / "dsp" / "bad.py").write_text("def f():\n    from vibsynth.app.service import serve\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert _violations() == ["vibsynth/dsp/bad.py:2: dsp imports vibsynth.app.service (a layer above)"]


@pytest.mark.parametrize("path", [p for p in _modules() if _layer(p) == "dsp"], ids=lambda p: p.name)
def test_the_science_does_no_io(path):
    io = [f"{path.name}:{line}: {module}" for line, module in _imports(path) if module.split(".")[0] in IO_MODULES]
    assert io == []
