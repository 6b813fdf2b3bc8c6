"""The OSCQuery tree: every method the handler answers is a node, each node keeps the proposal's rules."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from pythonoscquery.shared.osc_path_node import OSCPathNode

from vibsynth.control.osc.address import CHANNEL_METHODS
from vibsynth.settings.models import bounds_of

_JSON_TYPES = {"f": (float, int), "i": (int,), "s": (str,), "T": (bool,), "F": (bool,), "d": (float, int), "h": (int,)}


def walk(node: dict[str, Any]) -> Iterator[dict[str, Any]]:
    yield node
    for child in node.get("CONTENTS", {}).values():
        yield from walk(child)


def check_node(node: dict[str, Any], key: str | None = None) -> None:
    """The proposal's attribute rules (and python-oscquery's: a VALUE wherever ACCESS is not 0)."""
    path = node["FULL_PATH"]
    assert path.startswith("/") and " " not in path and "#" not in path
    if key is not None:
        assert path.rsplit("/", 1)[-1] == key
    assert node["ACCESS"] in (0, 1, 2, 3)
    assert isinstance(node["DESCRIPTION"], str) and node["DESCRIPTION"]
    if "CONTENTS" in node:
        assert node["ACCESS"] == 0 and "TYPE" not in node and "VALUE" not in node
        for name, child in node["CONTENTS"].items():
            assert child["FULL_PATH"] == (path.rstrip("/") + "/" + name)
        return
    types = node.get("TYPE", "")
    assert set(types) <= set(_JSON_TYPES)
    if "VALUE" in node:
        assert node["ACCESS"] in (1, 3), path
        assert isinstance(node["VALUE"], list) and len(node["VALUE"]) == len(types), path
        for tag, value in zip(types, node["VALUE"]):
            assert isinstance(value, _JSON_TYPES[tag]) and not (tag != "T" and isinstance(value, bool)), path
    else:
        assert node["ACCESS"] == 0, path
    for attribute in ("RANGE", "UNIT"):
        if attribute in node:
            assert types and isinstance(node[attribute], list) and len(node[attribute]) == len(types), path
    for spec, tag in zip(node.get("RANGE", []), types):
        if spec is None:
            continue
        assert set(spec) <= {"MIN", "MAX", "VALS"}, path
        if "MIN" in spec and "MAX" in spec:
            assert spec["MIN"] <= spec["MAX"], path
        if "VALS" in spec:
            assert all(isinstance(v, _JSON_TYPES[tag]) for v in spec["VALS"]), path


def test_every_node_keeps_the_attribute_rules(tree):
    root = tree.find("/").json(tree.context())
    nodes = list(walk(root))
    assert len(nodes) > 50
    for node in nodes:
        check_node(node)
    # a client no one here wrote reads every node (it raises on a VALUE without ACCESS and the reverse)
    parsed = OSCPathNode.from_json(root)
    assert {n.full_path for n in parsed} == {n["FULL_PATH"] for n in nodes}


def test_every_method_the_handler_answers_is_a_node(tree, handler, ctl):
    paths = set(tree.methods)
    for c in range(ctl.channels):
        for method in ("intensity", "balance", "texture", "glide", "mute", "preset", "speed", "get"):
            assert f"/vibsynth/ch/{c + 1}/{method}" in paths
    assert "/vibsynth/ch/5/intensity" not in paths  # the configured channels only
    for method in ("intensity", "panic", "status", "get", "sync", "notify", "ping", "learn", "monitor"):
        assert f"/vibsynth/{method}" in paths
    # parts that are not running answer "not available": no node until they run
    assert not any(p.startswith("/vibsynth/source/") for p in paths)  # no layout
    assert "/vibsynth/play" not in paths and "/vibsynth/follow/gain" not in paths
    assert all(p.rsplit("/", 1)[-1] in CHANNEL_METHODS for p in paths if p.startswith("/vibsynth/ch/"))


def test_ranges_come_from_the_settings_and_values_are_live(tree, ctl):
    ctx = tree.context()
    balance = tree.find("/vibsynth/ch/2/balance").json(ctx)
    assert balance["RANGE"] == [{"MIN": ctl.limits.balance_min, "MAX": ctl.limits.balance_max}]
    glide = tree.find("/vibsynth/glide").json(ctx)
    assert glide["RANGE"][0]["MAX"] == bounds_of("knobs.glide_ms")[1] and glide["UNIT"] == ["time.ms"]
    assert tree.find("/vibsynth/preset").json(ctx)["RANGE"] == [{"VALS": ["sand", "silk"]}]
    ctl.set_knob("intensity", 0.625, channels=(2,))
    ctl.load_preset("silk", channels=(1,))
    ctx = tree.context()
    assert tree.find("/vibsynth/ch/3/intensity").json(ctx)["VALUE"] == [0.625]
    assert tree.find("/vibsynth/ch/3/texture").json(ctx)["VALUE"] == [0.625, 0.0]
    assert tree.find("/vibsynth/ch/2/preset").json(ctx)["VALUE"] == ["silk"]
    assert tree.find("/vibsynth/sync").json(ctx).get("VALUE") is None


def test_a_new_preset_changes_the_preset_nodes_and_an_extra_table_adds_nodes(tree, presets, ctl):
    assert tree.refresh() == []
    presets.list.append("velvet")
    events = tree.refresh()
    changed = {p for c, p in events if c == "PATH_CHANGED"}
    assert changed == {"/vibsynth/preset"} | {f"/vibsynth/ch/{c + 1}/preset" for c in range(ctl.channels)}
    assert tree.find("/vibsynth/preset").json(tree.context())["RANGE"] == [{"VALS": ["sand", "silk", "velvet"]}]

    from vibsynth.control.oscquery.tree import NodeSpec

    class Avatar:
        def nodes(self):
            return {"/avatar/parameters/ChestL": NodeSpec("f", "proximity", lambda ctx: [0.25])}

    tree.register(Avatar())
    assert tree.refresh() == [("PATH_ADDED", "/avatar/parameters/ChestL")]
    check_node(tree.find("/avatar").json(tree.context()))
    assert tree.value("/avatar/parameters/ChestL", tree.context()) == ("f", [0.25])
