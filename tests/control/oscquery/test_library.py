"""Preset and clip nodes: one read-only node per library entry, added and removed with the files."""

from __future__ import annotations

from pythonoscquery.shared.osc_path_node import OSCPathNode

from tests.control.oscquery.test_tree import check_node, walk
from vibsynth.control.oscquery.library import LibraryNodes
from vibsynth.control.oscquery.methods import knob_ranges, method_nodes, reads
from vibsynth.control.oscquery.tree import Tree
from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir
from vibsynth.settings.library import PresetLibrary, shipped_presets_dir


def _tree(handler, ctl, presets, clips) -> Tree:
    tree = Tree(method_nodes(handler, presets.names, clips.names), reads(ctl), root_description="test")
    low, high = knob_ranges(ctl)
    tree.register(LibraryNodes("/vibsynth", presets, clips, intensity_range=low, balance_range=high))
    tree.refresh()
    return tree


def test_every_preset_and_clip_is_a_read_only_node_with_its_values(tmp_path, handler, ctl):
    presets = PresetLibrary(shipped_presets_dir(), tmp_path / "presets")
    clips = ClipLibrary(shipped_clips_dir(), tmp_path / "clips")
    tree = _tree(handler, ctl, presets, clips)
    ctx = tree.context()
    assert {p.rsplit("/", 1)[-1] for p in tree.methods if p.startswith("/vibsynth/presets/")} == set(presets.names())
    assert {p.rsplit("/", 1)[-1] for p in tree.methods if p.startswith("/vibsynth/clips/")} == set(clips.names())
    for name in presets.names():
        node = tree.find(f"/vibsynth/presets/{name}").json(ctx)
        preset = presets.get(name)
        assert node["VALUE"] == [preset.intensity, preset.balance] and node["ACCESS"] == 1
        assert node["RANGE"] == list(knob_ranges(ctl))
    impact = tree.find("/vibsynth/clips/impact").json(ctx)
    assert impact["VALUE"] == [clips.get("impact").duration_ms] and impact["UNIT"] == ["time.ms"]
    assert "/vibsynth/play s impact" in impact["DESCRIPTION"]
    root = tree.find("/").json(ctx)
    for node in walk(root):
        check_node(node)
    parsed = OSCPathNode.from_json(root)  # a client no one here wrote reads them
    assert "/vibsynth/clips/impact" in {n.full_path for n in parsed}


def test_a_file_added_edited_and_removed_is_added_changed_and_removed(tmp_path, handler, ctl):
    user = tmp_path / "presets"
    user.mkdir()
    presets = PresetLibrary(None, user)
    clips = ClipLibrary(None, tmp_path / "clips")
    tree = _tree(handler, ctl, presets, clips)
    path = "/vibsynth/presets/grit"
    assert tree.find(path) is None
    file = user / "grit.yaml"
    file.write_text("version: 1\nname: grit\nintensity: 0.25\nbalance: 1.5\n", encoding="utf-8")
    presets.reload()
    events = tree.refresh()
    assert ("PATH_ADDED", path) in events
    assert tree.value(path, tree.context()) == ("ff", [0.25, 1.5])
    file.write_text("version: 1\nname: grit\nintensity: 0.5\nbalance: 1.5\ndescription: coarse\n", encoding="utf-8")
    presets.reload()
    assert ("PATH_CHANGED", path) in tree.refresh()  # the description is cached by clients
    assert tree.value(path, tree.context()) == ("ff", [0.5, 1.5])
    file.write_text("version: 1\nname: grit\nintensity: 7\n", encoding="utf-8")  # broken: the last good stays
    presets.reload()
    assert all(p != path for _, p in tree.refresh()) and tree.value(path, tree.context()) == ("ff", [0.5, 1.5])
    file.unlink()
    presets.reload()
    assert ("PATH_REMOVED", path) in tree.refresh() and tree.find(path) is None
