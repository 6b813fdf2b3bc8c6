"""Presets: schema errors, migration, library layering, atomic writes, hot reload, shipped set, round trip."""

from __future__ import annotations

import importlib.util
import logging
import os
import time
from pathlib import Path

import numpy as np
import pytest

from tests.settings.helpers import Recorder, edit
from vibsynth.errors import PresetError
from vibsynth.settings.config import load_config
from vibsynth.settings.library import PresetLibrary, load_library, shipped_presets_dir
from vibsynth.settings.presets import (
    BALANCE_LIMIT,
    MIGRATIONS,
    SCHEMA_VERSION,
    Preset,
    load_preset,
    migrate,
    parse_preset,
    preset_to_yaml,
    save_preset,
)
from vibsynth.settings.reload import PresetWatcher

ROOT = Path(__file__).resolve().parents[2]
GOOD = (
    "version: 1\nname: x\ndescription: test\nintensity: 0.5\nbalance: -0.25\nglide_ms: 30\nprogram: 5\n"
    "tags: [a, b]\nprovenance: {recording: r.wav}\n"
)


def parse(text: str) -> Preset:
    return parse_preset(text, "x.yaml", name="x")


# --------------------------------------------------------------------------- schema
def test_good_preset_parses():
    p = parse(GOOD)
    assert (p.name, p.intensity, p.balance, p.glide_ms, p.program, p.tags) == ("x", 0.5, -0.25, 30.0, 5, ("a", "b"))
    assert p.provenance == {"recording": "r.wav"} and p.version == SCHEMA_VERSION


@pytest.mark.parametrize(
    "text, message",
    [
        ("intensity: 1.5\nbalance: 0\n", "x.yaml:1: intensity = 1.5: outside the allowed range [0, 1]"),
        ("intensity: -0.1\nbalance: 0\n", "x.yaml:1: intensity = -0.1: outside the allowed range [0, 1]"),
        (
            "intensity: loud\nbalance: 0\n",
            "x.yaml:1: intensity = 'loud': must be a number (allowed: a number in [0, 1])",
        ),
        ("intensity: true\nbalance: 0\n", "x.yaml:1: intensity = true: must be a number"),
        ("intensity: .nan\nbalance: 0\n", "x.yaml:1: intensity = nan: must be finite"),
        ("intensity: 0.5\nbalance: 4.5\n", "x.yaml:2: balance = 4.5: outside the allowed range [-4, 4] (knob units)"),
        ("intensity: 0.5\nbalance: .inf\n", "x.yaml:2: balance = inf: must be finite"),
        ("intensity: 0.5\nbalance: [1]\n", "x.yaml:2: balance = [1]: must be a number"),
        (
            "intensity: 0.5\nbalance: 0\nglide_ms: -1\n",
            "x.yaml:3: glide_ms = -1: outside the allowed range [0, 10000] ms",
        ),
        ("intensity: 0.5\nbalance: 0\nprogram: 128\n", "x.yaml:3: program = 128: outside the allowed range [0, 127]"),
        ("intensity: 0.5\nbalance: 0\nprogram: 1.5\n", "x.yaml:3: program = 1.5: must be an integer"),
        ("intensity: 0.5\nbalance: 0\ntags: rough\n", "x.yaml:3: tags = 'rough': must be a list, e.g. tags: [rough]"),
        ("intensity: 0.5\nbalance: 0\ntags:\n  - ok\n  - '!bad'\n", "x.yaml:5: tags[1] = '!bad'"),
        ("intensity: 0.5\nbalance: 0\ntags: {a: 1}\n", "x.yaml:3: tags = {'a': 1}: must be a list"),
        ("intensity: 0.5\nbalance: 0\ndescription: [1]\n", "x.yaml:3: description = [1]: must be text"),
        ("intensity: 0.5\nbalance: 0\nprovenance: file.wav\n", "x.yaml:3: provenance = 'file.wav': must be a mapping"),
        ("intensity: 0.5\nbalance: 0\ncolour: red\n", "x.yaml:3: unknown key 'colour' (allowed: version, name,"),
        ("intensity: 0.5\nbalance: 0\nglide: 20\n", "x.yaml:3: unknown key 'glide'; did you mean 'glide_ms'?"),
        ("intensity: 0.5\n", "x.yaml: missing key 'balance' (allowed: a number in [-4, 4])"),
        ("balance: 0\n", "x.yaml: missing key 'intensity' (allowed: a number in [0, 1])"),
        ("name: y\nintensity: 0.5\nbalance: 0\n", "x.yaml:1: name = 'y' does not match the file name x.yaml"),
        ("version: 9\nintensity: 0.5\nbalance: 0\n", "x.yaml:1: version = 9: written by a newer vibsynth"),
        ("version: -1\nintensity: 0.5\nbalance: 0\n", "x.yaml:1: version = -1: outside the allowed range 0..1"),
        ("version: one\nintensity: 0.5\nbalance: 0\n", "x.yaml:1: version = 'one': must be an integer"),
        ("intensity: 0.5\nbalance: 0\nbalance: 1\n", "x.yaml:3: key 'balance' appears twice (first on line 2)"),
        ("intensity: 0.5\n  balance: 0\n", "x.yaml:2:10: YAML syntax error"),
        ("", "x.yaml: the file is empty"),
        ("- 1\n- 2\n", "x.yaml: a preset must be a mapping"),
    ],
)
def test_schema_errors_name_file_line_key_value_range(text, message):
    with pytest.raises(PresetError) as info:
        parse(text)
    assert message in str(info.value)


def test_bad_name_is_refused():
    with pytest.raises(PresetError, match=r"name = 'a b': must be 1-64 letters"):
        parse_preset("name: a b\nintensity: 0.5\nbalance: 0\n", "a b.yaml")


@pytest.mark.parametrize("seed", range(5))
def test_random_valid_presets_round_trip_through_yaml(seed, tmp_path):
    rng = np.random.default_rng(seed)
    for i in range(20):
        p = Preset(
            name=f"p{i}",
            intensity=float(rng.uniform(0, 1)),
            balance=float(rng.uniform(-BALANCE_LIMIT, BALANCE_LIMIT)),
            glide_ms=None if rng.random() < 0.3 else float(rng.uniform(0, 10000)),
            program=None if rng.random() < 0.5 else int(rng.integers(0, 128)),
            tags=tuple(f"t{j}" for j in range(int(rng.integers(0, 4)))),
            description="d" * int(rng.integers(0, 50)),
            provenance={"n": int(rng.integers(0, 9)), "x": [1.5, "a"]},
        )
        path = save_preset(p, tmp_path / f"p{i}.yaml")
        assert load_preset(path) == p


# --------------------------------------------------------------------------- migration
def test_v0_file_without_version_migrates_to_v1(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text("intensity: 0.4\nbalance: 0.7\n")
    p = load_preset(path)
    assert (p.version, p.name, p.intensity, p.balance) == (1, "old", 0.4, 0.7)
    save_preset(p, path)
    assert path.read_text().splitlines()[1] == "version: 1"
    assert load_preset(path) == p


def test_migration_chain_covers_every_older_version():
    assert sorted(MIGRATIONS) == list(range(SCHEMA_VERSION))
    assert migrate({"intensity": 0.1, "balance": 0}) == {"intensity": 0.1, "balance": 0, "version": 1}
    assert migrate({"version": 1, "intensity": 0.1, "balance": 0})["version"] == 1


# --------------------------------------------------------------------------- atomic writes
def test_save_is_atomic_and_never_writes_invalid(tmp_path, monkeypatch):
    path = tmp_path / "a.yaml"
    save_preset(Preset("a", 0.5, 0.0), path)
    before = path.read_text()
    with pytest.raises(PresetError):
        save_preset(Preset("a", 1.5, 0.0), path)  # invalid: refused before writing
    assert path.read_text() == before

    import vibsynth.formats.files as vio

    def crash(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(vio.os, "replace", crash)
    with pytest.raises(PresetError, match=r"a.yaml: cannot write \(disk full\)"):
        save_preset(Preset("a", 0.9, 0.0), path)
    assert path.read_text() == before  # the old file is intact
    assert [p.name for p in tmp_path.iterdir()] == ["a.yaml"]  # no temp file left


def test_save_refuses_a_file_name_that_does_not_match(tmp_path):
    with pytest.raises(PresetError, match="does not match the file name other.yaml"):
        save_preset(Preset("a", 0.5, 0.0), tmp_path / "other.yaml")


# --------------------------------------------------------------------------- library
@pytest.fixture
def dirs(tmp_path):
    shipped, user = tmp_path / "shipped", tmp_path / "user"
    shipped.mkdir()
    for name, balance, program in (("alpha", -0.5, 0), ("beta", 0.0, 1), ("gamma", 0.5, None)):
        save_preset(Preset(name, 0.5, balance, program=program), shipped / f"{name}.yaml")
    return shipped, user


def test_user_preset_overrides_shipped(dirs):
    shipped, user = dirs
    lib = PresetLibrary(shipped, user)
    assert lib.names() == ["alpha", "beta", "gamma"] and lib.get("beta").origin == "shipped"
    save_preset(Preset("beta", 0.9, 1.0), user / "beta.yaml")
    save_preset(Preset("delta", 0.1, 2.0), user / "delta.yaml")
    assert lib.reload() == {"beta": "changed", "delta": "added"}
    assert lib.get("beta").intensity == 0.9 and lib.get("beta").origin == "user"
    (user / "beta.yaml").unlink()
    assert lib.reload() == {"beta": "changed"}
    assert lib.get("beta").origin == "shipped"


def test_get_unknown_lists_close_names(dirs):
    lib = PresetLibrary(*dirs)
    with pytest.raises(PresetError, match=r"unknown preset 'alpah'; did you mean alpha\?"):
        lib.get("alpah")
    with pytest.raises(PresetError, match=r"did you mean alpha"):
        lib.get("ALPHA")
    with pytest.raises(PresetError, match=r"unknown preset 'zzz' \(3 presets"):
        lib.get("zzz")


def test_by_program_explicit_then_free_numbers_in_name_order(dirs):
    shipped, user = dirs
    lib = PresetLibrary(shipped, user)
    assert lib.program_map() == {0: "alpha", 1: "beta", 2: "gamma"}
    save_preset(Preset("aaa", 0.5, 0.0), user / "aaa.yaml")
    save_preset(Preset("zed", 0.5, 0.0, program=1), user / "zed.yaml")
    lib.reload()
    mapping = lib.program_map()
    assert mapping[1] == "zed"  # user's explicit program wins the clash
    assert mapping[0] == "alpha" and mapping[2] == "aaa" and mapping[3] == "gamma"
    assert lib.by_program(1).name == "zed"
    with pytest.raises(PresetError, match="outside the allowed range 0..127"):
        lib.by_program(128)
    with pytest.raises(PresetError, match="no preset for program 99"):
        lib.by_program(99)


def test_broken_file_at_startup_is_reported_not_fatal(dirs, caplog):
    shipped, user = dirs
    user.mkdir()
    (user / "bad.yaml").write_text("intensity: 2\nbalance: 0\n")
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"):
        lib = PresetLibrary(shipped, user)
    assert "bad" not in lib
    assert "bad.yaml:1: intensity = 2" in lib.errors[str(user / "bad.yaml")]
    assert "bad.yaml:1: intensity = 2" in caplog.text


def test_load_library_uses_config_user_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    config = load_config(overrides={"presets.user_dir": str(tmp_path / "mine")}, env={}, user_file=False)
    lib = load_library(config.settings)
    assert lib.user_dir == tmp_path / "mine" and lib.shipped_dir == shipped_presets_dir()
    assert len(lib) >= 12


def test_default_user_dir_is_platform_data_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    lib = load_library(load_config(env={}, user_file=False).settings)
    assert lib.user_dir == tmp_path / "data" / "vibsynth" / "presets"


# --------------------------------------------------------------------------- hot reload
def test_watcher_edit_break_fix_delete(dirs, caplog):
    shipped, user = dirs
    user.mkdir()
    target = user / "mine.yaml"
    save_preset(Preset("mine", 0.3, 0.1), target)
    lib = PresetLibrary(shipped, user)
    rec = Recorder()
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"), PresetWatcher(lib, rec, interval_s=0.05):
        edit(target, "version: 1\nintensity: 0.6\nbalance: 0.1\n")  # edit
        assert rec.wait() == ["mine"] and lib.get("mine").intensity == 0.6

        edit(target, "version: 1\nintensity: 0.7\nbalance: 9\n")  # broken edit
        # an in-place write may be seen half done first ("the file is empty"): wait for its final state
        deadline = time.monotonic() + 5.0
        while "balance = 9" not in lib.errors.get(str(target), "") and time.monotonic() < deadline:
            time.sleep(0.01)
        assert "mine.yaml:3: balance = 9" in lib.errors[str(target)]
        assert "mine.yaml:3: balance = 9" in caplog.text
        assert lib.get("mine").intensity == 0.6  # last good version kept
        assert rec.calls == []  # nothing changed for the service

        edit(target, "version: 1\nintensity: 0.8\nbalance: 0.2\n")  # fix
        assert rec.wait() == ["mine"] and lib.get("mine").balance == 0.2 and not lib.errors

        save_preset(Preset("extra", 0.2, 0.0), user / "extra.yaml")  # addition (atomic write)
        assert rec.wait() == ["extra"] and "extra" in lib

        target.unlink()  # removal
        assert rec.wait() == ["mine"] and "mine" not in lib
        assert lib.names() == ["alpha", "beta", "extra", "gamma"]  # nothing else lost


def test_same_size_same_mtime_edit_is_seen_by_the_one_racy_reread(dirs, monkeypatch):
    """An in-place edit of the same size within the timestamp resolution leaves (mtime, size,
    inode) unchanged: a file read within RACY_NS of its mtime is read once more after that."""
    import vibsynth.settings.library as vp

    shipped, user = dirs
    user.mkdir()
    target = user / "m.yaml"
    target.write_text("intensity: 0.25\nbalance: 0\n")
    stat = target.stat()
    lib = PresetLibrary(shipped, user, load=False)
    lib._clock = lambda: stat.st_mtime_ns + 1_000_000  # read 1 ms after the write: racy
    lib.reload()
    rec = Recorder()
    watcher = PresetWatcher(lib, rec)
    assert watcher.poll() == {}
    target.write_text("intensity: 0.75\nbalance: 0\n")
    os.utime(target, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert target.stat()[1:] == stat[1:] and target.stat().st_mtime_ns == stat.st_mtime_ns
    assert watcher.poll() == {}  # indistinguishable by stat yet
    reads = count_reads(monkeypatch)
    lib._clock = lambda: stat.st_mtime_ns + vp.RACY_NS  # the window has passed
    assert watcher.poll() == {"m": "changed"} and rec.calls == ["m"] and reads.count(target) == 1
    reads.clear()  # (the fixture's shipped files were written just before: re-read once too)
    assert watcher.poll() == {} and reads == []  # once, not at every poll


def test_callback_errors_do_not_stop_the_watcher(dirs, caplog):
    shipped, user = dirs
    user.mkdir()
    lib = PresetLibrary(shipped, user)
    seen: list[str] = []

    def flaky(name: str) -> None:
        seen.append(name)
        raise RuntimeError("service bug")

    watcher = PresetWatcher(lib, flaky)
    save_preset(Preset("one", 0.5, 0.0), user / "one.yaml")
    save_preset(Preset("two", 0.5, 0.0), user / "two.yaml")
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"):
        assert watcher.poll() == {"one": "added", "two": "added"}
    assert seen == ["one", "two"] and "on_change callback failed" in caplog.text


def test_watcher_reapplies_through_controller(dirs):
    """The service's wiring: on_change -> Controller.reapply_preset glides the playing channels."""
    from vibsynth.control.controller import Controller

    class FakeEngine:
        channels, fs = 2, 48000.0
        applied_seq = frame_position = 0

        def __init__(self) -> None:
            self.commands: list = []

        def submit(self, command) -> int:
            self.commands.append(command)
            return len(self.commands)

    shipped, user = dirs
    user.mkdir()
    lib = PresetLibrary(shipped, user)
    engine = FakeEngine()
    controller = Controller(engine, preset_resolver=lib.get)
    controller.load_preset("beta", channels=[1])
    watcher = PresetWatcher(lib, lambda name: controller.reapply_preset(name))
    save_preset(Preset("beta", 0.8, 0.7, glide_ms=100), user / "beta.yaml")
    engine.commands.clear()
    watcher.poll()
    knobs = {(c.name, c.value, c.channels, c.glide_s) for c in engine.commands}
    assert knobs == {("balance", 0.7, (1,), 0.1), ("intensity", 0.8, (1,), 0.1)}


def test_removed_playing_preset_logs_a_warning_and_keeps_playing(dirs, caplog):
    from vibsynth.control.controller import Controller

    class FakeEngine:
        channels, fs = 1, 48000.0
        applied_seq = frame_position = 0

        def submit(self, command) -> int:
            return 1

    shipped, user = dirs
    user.mkdir()
    save_preset(Preset("solo", 0.4, 0.3), user / "solo.yaml")
    lib = PresetLibrary(shipped, user)
    controller = Controller(FakeEngine(), preset_resolver=lib.get)
    controller.load_preset("solo")
    watcher = PresetWatcher(lib, lambda name: controller.reapply_preset(name))
    (user / "solo.yaml").unlink()
    with caplog.at_level(logging.WARNING, logger="vibsynth.settings"):
        assert watcher.poll() == {"solo": "removed"}
    assert "preset 'solo' removed: unknown preset 'solo'" in caplog.text and "Traceback" not in caplog.text
    assert controller.get("intensity") == 0.4  # still playing


def test_watcher_rejects_bad_interval(dirs):
    with pytest.raises(PresetError, match="outside the allowed range"):
        PresetWatcher(PresetLibrary(*dirs), print, interval_s=0)


# --------------------------------------------------------------------------- hot reload: bounded work (issue 12)
def count_reads(monkeypatch) -> list[Path]:
    """Record every file the one YAML loader opens (``vibsynth.formats.files._read_capped``)."""
    import vibsynth.formats.files as vio

    reads: list[Path] = []
    original = vio._read_capped

    def counting(path, **kwargs):
        reads.append(Path(path))
        return original(path, **kwargs)

    monkeypatch.setattr(vio, "_read_capped", counting)
    return reads


def junk_text(rng: np.random.Generator, n_bytes: int) -> str:
    """Printable YAML-ish junk (comment lines) of exactly ``n_bytes``."""
    letters = np.frombuffer(b"abcdefghijklmnopqrstuvwxyz ", dtype=np.uint8)
    body = letters[rng.integers(0, letters.size, n_bytes)].copy()
    body[::64] = ord("\n")
    body[1::64] = ord("#")
    return body.tobytes().decode()


def lines_about(caplog, fragment: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if fragment in r.getMessage()]


def test_unchanged_files_are_never_reread(dirs, monkeypatch):
    shipped, user = dirs
    user.mkdir()
    save_preset(Preset("mine", 0.3, 0.1), user / "mine.yaml")
    lib = PresetLibrary(shipped, user, load=False)
    lib._clock = lambda: time.time_ns() + 10 * 10**9  # past the racy window: only stat() changes count
    lib.reload()
    watcher = PresetWatcher(lib, Recorder())
    reads = count_reads(monkeypatch)
    for _ in range(20):
        assert watcher.poll() == {}
    assert reads == []


def test_file_over_the_cap_is_never_read_and_logged_once(dirs, monkeypatch, caplog, rng):
    import vibsynth.settings.library as vp

    shipped, user = dirs
    user.mkdir()
    big = user / "big.yaml"
    big.write_text(junk_text(rng, vp.MAX_PRESET_BYTES + 1))
    reads = count_reads(monkeypatch)
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"):
        lib = PresetLibrary(shipped, user)
        watcher = PresetWatcher(lib, Recorder())
        for k in range(30):
            assert watcher.poll() == {}
            if k == 10:  # still growing (a copy in progress): no new line
                with open(big, "a") as fh:
                    fh.write(junk_text(rng, 4096))
    assert big not in reads
    assert lines_about(caplog, "big.yaml") == [
        f"{big}: {vp.MAX_PRESET_BYTES + 1:,} bytes, over the 1 MiB limit for a preset; not read; skipped"
    ]
    assert "over the 1 MiB limit" in lib.errors[str(big)] and lib.names() == ["alpha", "beta", "gamma"]

    # it becomes a preset: read and added; too large again: one new line, last good version kept
    edit(big, "version: 1\nintensity: 0.25\nbalance: 0.5\n")
    assert watcher.poll() == {"big": "added"} and not lib.errors
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"):
        edit(big, junk_text(rng, 2 * vp.MAX_PRESET_BYTES))
        for _ in range(10):
            assert watcher.poll() == {}
    assert len(lines_about(caplog, "big.yaml")) == 1 and "keeping the last good version" in caplog.text
    assert lib.get("big").intensity == 0.25 and reads.count(big) == 1


def test_same_size_edit_with_a_new_mtime_is_reloaded(dirs, monkeypatch):
    shipped, user = dirs
    user.mkdir()
    target = user / "m.yaml"
    target.write_text("intensity: 0.25\nbalance: 0\n")
    before = target.stat()
    lib = PresetLibrary(shipped, user, load=False)
    lib._clock = lambda: before.st_mtime_ns + 10 * 10**9  # not racy
    lib.reload()
    watcher = PresetWatcher(lib, Recorder())
    reads = count_reads(monkeypatch)
    with open(target, "r+") as fh:  # in place: same inode, same size
        fh.write("intensity: 0.75\nbalance: 0\n")
    os.utime(target, ns=(before.st_atime_ns, before.st_mtime_ns + 1))
    after = target.stat()
    assert (after.st_size, after.st_ino) == (before.st_size, before.st_ino)
    assert watcher.poll() == {"m": "changed"} and lib.get("m").intensity == 0.75 and reads == [target]


def test_atomic_replace_with_same_size_and_mtime_is_seen_by_inode(dirs):
    shipped, user = dirs
    user.mkdir()
    target = user / "m.yaml"
    target.write_text("intensity: 0.25\nbalance: 0\n")
    before = target.stat()
    lib = PresetLibrary(shipped, user, load=False)
    lib._clock = lambda: before.st_mtime_ns + 10 * 10**9
    lib.reload()
    watcher = PresetWatcher(lib, Recorder())
    replacement = user / ".m.yaml.part"
    replacement.write_text("intensity: 0.75\nbalance: 0\n")
    os.utime(replacement, ns=(before.st_atime_ns, before.st_mtime_ns))
    os.replace(replacement, target)
    assert target.stat().st_ino != before.st_ino
    assert watcher.poll() == {"m": "changed"}


def test_unlistable_folder_is_reported_once_and_its_presets_kept(dirs, monkeypatch, caplog):
    """Tests run as root, for whom chmod 000 changes nothing: os.scandir raises as it would."""
    import vibsynth.settings.library as vp

    shipped, user = dirs
    user.mkdir()
    save_preset(Preset("mine", 0.3, 0.1), user / "mine.yaml")
    lib = PresetLibrary(shipped, user)
    watcher = PresetWatcher(lib, Recorder())
    real_scandir = os.scandir
    denied = {"on": True}

    def scandir(path):
        if denied["on"] and Path(path) == user:
            raise PermissionError(13, "Permission denied", str(path))
        return real_scandir(path)

    monkeypatch.setattr(vp.os, "scandir", scandir)
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"):
        for _ in range(20):
            assert watcher.poll() == {}
        assert "mine" in lib  # a permission glitch does not remove what may be playing
        denied["on"] = False
        save_preset(Preset("other", 0.2, 0.0), user / "other.yaml")
        for _ in range(5):
            watcher.poll()
    assert lines_about(caplog, "preset folder") == [
        f"preset folder {user}: cannot list it (Permission denied); keeping the presets read from it before "
        "until it can be listed again",
        f"preset folder {user}: can be listed again",
    ]
    assert {"mine", "other"} <= set(lib.names())


def test_symlink_loops_are_reported_once(tmp_path, caplog):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)  # the user folder is a symbolic link to itself
    folder = tmp_path / "presets"
    folder.mkdir()
    (folder / "self.yaml").symlink_to(folder / "self.yaml")  # a preset file that is a loop
    (folder / "ok.yaml").write_text("intensity: 0.5\nbalance: 0\n")
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"):
        looped = PresetLibrary(folder, loop)
        watcher = PresetWatcher(looped, Recorder())
        for _ in range(10):
            watcher.poll()
    assert looped.names() == ["ok"]
    assert lines_about(caplog, str(loop)) == [
        f"preset folder {loop}: cannot list it (symbolic link loop); keeping the presets read from it before "
        "until it can be listed again"
    ]
    assert lines_about(caplog, "self.yaml") == [f"{folder / 'self.yaml'}: cannot read (symbolic link loop); skipped"]


def test_a_poll_reads_a_bounded_number_of_files(dirs, monkeypatch):
    import vibsynth.settings.library as vp

    shipped, user = dirs
    user.mkdir()
    lib = PresetLibrary(shipped, user)
    lib._clock = lambda: time.time_ns() + 10 * 10**9  # past the racy window: a slow machine re-reads nothing
    lib.reload()  # the shipped files' one racy re-read, before counting
    watcher = PresetWatcher(lib, Recorder())
    n = 2 * vp.POLL_READ_FILES + 20
    for i in range(n):
        save_preset(Preset(f"p{i:03d}", 0.5, 0.0), user / f"p{i:03d}.yaml")
    reads = count_reads(monkeypatch)
    counts = []
    while len(lib) < n + 3:
        before = len(reads)
        watcher.poll()
        counts.append(len(reads) - before)
        assert len(counts) < 10
    assert counts == [vp.POLL_READ_FILES, vp.POLL_READ_FILES, 20]


def test_files_per_folder_are_capped_with_one_line(dirs, monkeypatch, caplog):
    import vibsynth.settings.library as vp

    shipped, user = dirs
    user.mkdir()
    monkeypatch.setattr(vp, "MAX_FILES_PER_FOLDER", 5)
    for i in range(8):
        save_preset(Preset(f"p{i}", 0.5, 0.0), user / f"p{i}.yaml")
    with caplog.at_level(logging.INFO, logger="vibsynth.settings"):
        lib = PresetLibrary(None, user)
        watcher = PresetWatcher(lib, Recorder())
        for _ in range(5):
            watcher.poll()
    assert len(lib) == 5
    assert lines_about(caplog, "preset files") == [f"preset folder {user}: more than 5 preset files; only 5 are used"]


def test_bomb_preset_is_refused_fast_and_named(dirs):
    shipped, user = dirs
    user.mkdir()
    bomb = user / "bomb.yaml"
    bomb.write_text(BOMB)
    started = time.perf_counter()
    lib = PresetLibrary(shipped, user)
    assert time.perf_counter() - started < 0.5
    assert lib.errors[str(bomb)].startswith(
        f"{bomb}:2:8: YAML alias '*a' (anchor '&a' on line 1): aliases are not allowed in a preset"
    )


BOMB = (
    "\n".join(
        ["a: &a [x,x,x,x,x,x,x,x,x]"]
        + [f"{b}: &{b} [" + ",".join([f"*{a}"] * 9) + "]" for a, b in zip("abcdefgh", "bcdefghi")]
    )
    + "\n"
)


# --------------------------------------------------------------------------- shipped presets
def test_shipped_presets_are_valid_and_span_the_balance_range():
    lib = PresetLibrary(shipped_presets_dir(), None)
    presets = lib.presets()
    assert len(presets) >= 12 and not lib.errors
    balances = sorted(p.balance for p in presets)
    assert balances[0] < -0.9 and balances[-1] > 0.9
    assert max(np.diff(balances)) < 0.25, "gaps in the balance range"
    for p in presets:
        prov = p.provenance
        for key in ("dataset", "texture", "n_models", "median_t1", "median_balance", "basis_id", "citation"):
            assert key in prov, (p.name, key)
        assert 0.05 <= p.intensity <= 1.0
        assert abs(p.balance - prov["median_balance"]) < 1e-3
        if prov["noise_floor_caveat"]:
            assert "noise floor" in p.description
    assert sorted(p.program for p in presets) == list(range(len(presets)))
    assert [p.name for p in sorted(presets, key=lambda p: p.program)] == [
        p.name for p in sorted(presets, key=lambda p: p.balance)
    ]


def test_repo_presets_folder_is_the_package_data():
    assert (ROOT / "presets").resolve() == shipped_presets_dir().resolve()


def test_shipped_basis_id_matches():
    from vibsynth.formats.basis_file import default_basis

    ids = {p.provenance["basis_id"] for p in PresetLibrary(shipped_presets_dir(), None).presets()}
    assert ids == {default_basis().id}


@pytest.mark.shared
def test_shipped_presets_regenerate_identically(hatt_psd):
    spec = importlib.util.spec_from_file_location("make_presets", ROOT / "scripts" / "make_presets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    built = module.build_presets(hatt_psd)
    current = {p.name: p.read_text(encoding="utf-8") for p in shipped_presets_dir().glob("*.yaml")}
    assert built == current, "run: python scripts/make_presets.py"


# --------------------------------------------------------------------------- round trip
def test_preset_yaml_has_schema_key_order():
    text = preset_to_yaml(parse(GOOD))
    keys = [line.split(":")[0] for line in text.splitlines() if line and line[0] not in " #-"]
    assert keys == [
        "version",
        "name",
        "description",
        "intensity",
        "balance",
        "glide_ms",
        "program",
        "tags",
        "provenance",
    ]
