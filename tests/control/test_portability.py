"""Static guards over the package source: calls that break a platform or reach into private APIs."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "vibsynth"
SOURCES = sorted(PACKAGE.rglob("*.py"))


def attribute_uses(tree: ast.AST) -> list[tuple[str, str, int]]:
    """(object name, attribute, line) of every ``name.attr`` expression."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            out.append((node.value.id, node.attr, node.lineno))
    return out


def string_attrs(tree: ast.AST) -> list[tuple[str, int]]:
    """Attribute names read with ``getattr(obj, "name", ...)``."""
    out = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in ("getattr", "hasattr", "setattr")
            and len(node.args) >= 2
            and isinstance(node.args[1], ast.Constant)
            and isinstance(node.args[1].value, str)
        ):
            out.append((node.args[1].value, node.lineno))
    return out


@pytest.fixture(scope="module")
def trees():
    assert SOURCES, f"no sources under {PACKAGE}"
    return {path.relative_to(PACKAGE.parent): ast.parse(path.read_text(encoding="utf-8")) for path in SOURCES}


def test_no_unix_only_select_calls(trees):
    """select.poll/epoll/kqueue do not exist on Windows: sockets wait through selectors (or select.select)."""
    found = [
        f"{path}:{line}: select.{attr}"
        for path, tree in trees.items()
        for name, attr, line in attribute_uses(tree)
        if name == "select" and attr in ("poll", "epoll", "devpoll", "kqueue")
    ]
    assert found == []


def test_nothing_changes_the_gil_switch_interval(trees):
    """The real-time path is compiled and needs no GIL: no sys.setswitchinterval anywhere."""
    found = [
        f"{path}:{line}"
        for path, tree in trees.items()
        for name, attr, line in attribute_uses(tree)
        if name == "sys" and attr == "setswitchinterval"
    ]
    assert found == []


def test_no_private_mido_port_attributes(trees):
    """mido ports are used through their public API only (``_rt``, ``_device_type``, ``_queue`` are mido's own)."""
    private = {"_rt", "_device_type", "_queue", "_callback", "_callback_wrapper"}
    found = []
    for path, tree in trees.items():
        for name, attr, line in attribute_uses(tree):
            if attr in private and name != "self":
                found.append(f"{path}:{line}: {name}.{attr}")
        found += [f"{path}:{line}: getattr(..., {attr!r})" for attr, line in string_attrs(tree) if attr in private]
    assert found == []
