"""The package's layers: imports only go down, and no modules import each other in a circle.

Every ``import`` in every module is checked, including the lazy ones inside functions, so a
deferred import cannot hide a dependency that runs back up the layers (docs/architecture.md,
"Layout"), nor a circle between modules: a function-level import that dodges a circle at
import time is still the circle, and so is an import under ``if TYPE_CHECKING:`` (the types
depend on each other even where the code does not). One exception: a package's
``__init__.py`` may name, for typing only, the type of a module inside it (a registry naming
what registers itself); a submodule always depends on its package, whose ``__init__`` runs first.
Below ``app`` nothing imports the package's face (``import vibsynth``, ``from vibsynth import
__version__``): the version is in ``vibsynth/_version.py``.
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vibsynth"

#: What each layer may import (besides itself and the modules at the root: ``errors``, ``_version``).
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
#: The layers that may import the package's face (``vibsynth/__init__.py``: the public API).
FACE_USERS = {"app", "cli"}
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
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module == "vibsynth":
            for alias in node.names:  # a subpackage or module, else a name of the face (vibsynth/__init__.py)
                sub = (PACKAGE / alias.name).is_dir() or (PACKAGE / f"{alias.name}.py").is_file()
                found.append((node.lineno, f"vibsynth.{alias.name}" if sub else "vibsynth"))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
    return found


def _violations() -> list[str]:
    problems = []
    for path in _modules():
        layer = _layer(path)
        if layer is None:
            continue  # the package root, errors.py and _version.py
        assert layer in ALLOWED, f"{path}: folder {layer!r} is not in the layer table (docs/architecture.md)"
        where = path.relative_to(PACKAGE.parent)
        for line, module in _imports(path):
            parts = module.split(".")
            if module == "vibsynth" and layer not in FACE_USERS:
                problems.append(f"{where}:{line}: {layer} imports the package's face (vibsynth/__init__.py)")
            if parts[0] != "vibsynth" or len(parts) < 2:
                continue
            target = parts[1]
            if target != layer and target not in ALLOWED[layer] and target in ALLOWED:
                problems.append(f"{where}:{line}: {layer} imports {module} (a layer above)")
    return problems


def _module_names() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package (a package by its ``__init__.py``)."""
    names = {}
    for path in _modules():
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        names[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return names


def _type_checking_lines(tree: ast.Module) -> set[int]:
    """Lines of the imports under ``if TYPE_CHECKING:`` (``typing.TYPE_CHECKING`` too)."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
            for inner in node.body:
                lines.update(sub.lineno for sub in ast.walk(inner) if isinstance(sub, (ast.Import, ast.ImportFrom)))
    return lines


def _edges(names: dict[str, Path]) -> dict[str, dict[str, int]]:
    """Module -> {module of the package it imports (module level, in a function or for typing): line}.

    A package's typing-only import of a module inside it is left out (the registry exception).
    """

    def known(dotted: str) -> str | None:
        while dotted and dotted not in names:
            dotted = dotted.rpartition(".")[0]
        return dotted or None

    edges: dict[str, dict[str, int]] = {}
    for name, path in names.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        typing_only = _type_checking_lines(tree)
        out = edges.setdefault(name, {})
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if isinstance(node, ast.Import):
                targets = [known(alias.name) for alias in node.names]
            else:
                package = name if path.name == "__init__.py" else name.rpartition(".")[0]
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                module = ".".join([*base, node.module] if node.module else base)
                targets = [known(f"{module}.{alias.name}") or known(module) for alias in node.names]
            for target in targets:
                if target is None or target == name or not target.startswith(PACKAGE.name):
                    continue
                if node.lineno in typing_only and path.name == "__init__.py" and target.startswith(f"{name}."):
                    continue  # a package naming the type of its own module (a registry)
                out.setdefault(target, node.lineno)
    return edges


def _circles() -> list[str]:
    """One line per circle of imports: ``a (a.py:3) -> b (b.py:9) -> a``; empty without any."""
    names = _module_names()
    edges = _edges(names)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in edges[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return [_one_circle(component, edges, names) for component in sorted(found)]


def _one_circle(component: list[str], edges: dict[str, dict[str, int]], names: dict[str, Path]) -> str:
    """A shortest circle through the first module of a strongly connected component, with the import lines."""
    start, members = component[0], set(component)
    paths = {start: [start]}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for nxt in sorted(edges[node]):
            if nxt == start:
                path = paths[node]
                hops = [
                    f"{a} ({names[a].relative_to(PACKAGE.parent)}:{edges[a][b]})"
                    for a, b in zip(path, [*path[1:], start])
                ]
                return " -> ".join([*hops, start])
            if nxt in members and nxt not in paths:
                paths[nxt] = [*paths[node], nxt]
                queue.append(nxt)
    raise AssertionError(f"no circle through {start}")  # pragma: no cover - a component of 2+ has one


def test_imports_only_go_down_the_layers():
    assert _violations() == []


def test_no_modules_import_each_other_in_a_circle():
    assert _circles() == []


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


def test_the_checker_sees_the_face_imported_below_app(tmp_path, monkeypatch):
    fake = tmp_path / "vibsynth"
    for folder in ("control", "app"):
        (fake / folder).mkdir(parents=True)
        (fake / folder / "status.py").write_text("from vibsynth import __version__\nfrom vibsynth._version import v\n")
    (fake / "control" / "face.py").write_text("def f():\n    import vibsynth\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert _violations() == [
        "vibsynth/control/face.py:2: control imports the package's face (vibsynth/__init__.py)",
        "vibsynth/control/status.py:1: control imports the package's face (vibsynth/__init__.py)",
    ]


def test_the_checker_sees_a_circle_through_a_lazy_import_or_type_checking_but_not_a_registry(tmp_path, monkeypatch):
    fake = tmp_path / "vibsynth"
    (fake / "settings").mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    typing_import = "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from {} import {}\n"
    (fake / "settings" / "__init__.py").write_text(typing_import.format("vibsynth.settings.registry", "R"))
    (fake / "settings" / "registry.py").write_text("from vibsynth import settings\n")  # the registry exception
    (fake / "settings" / "models.py").write_text("X = 1\n\n\ndef check():\n    from vibsynth.settings.files import y\n")
    (fake / "settings" / "files.py").write_text("from vibsynth.settings import models\n")
    (fake / "settings" / "typed.py").write_text(typing_import.format("vibsynth.settings.user", "U"))
    (fake / "settings" / "user.py").write_text("from .typed import T\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert _circles() == [
        "vibsynth.settings.files (vibsynth/settings/files.py:1) -> "
        "vibsynth.settings.models (vibsynth/settings/models.py:5) -> vibsynth.settings.files",
        "vibsynth.settings.typed (vibsynth/settings/typed.py:4) -> "
        "vibsynth.settings.user (vibsynth/settings/user.py:1) -> vibsynth.settings.typed",
    ]


def _folders(root: Path) -> list[str]:
    """Every folder of the package and the repository's top-level folders (``vibsynth/dsp/``, ``docs/``).

    The files git knows or would add (tracked, or new and not ignored), so caches and builds are
    not folders of the project; a top-level link to a folder (``presets``) is one.
    """
    if shutil.which("git") is None or not (root / ".git").exists():
        pytest.skip("needs the git checkout")
    listed = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
        cwd=root,
        capture_output=True,
        check=True,
    ).stdout.decode()
    folders = set()
    for name in filter(None, listed.split("\0")):
        parts = Path(name).parts
        if not (root / name).exists():
            continue  # deleted in the work tree
        if parts[0] == PACKAGE.name:
            folders.update("/".join(parts[:n]) + "/" for n in range(1, len(parts)))
        elif len(parts) > 1 or (root / name).is_dir():
            folders.add(parts[0] + "/")
    return sorted(folders)


def test_every_folder_is_named_in_the_architecture_page():
    root = PACKAGE.parent
    text = (root / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert [folder for folder in _folders(root) if f"`{folder}`" not in text] == []
