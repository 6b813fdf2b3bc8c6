"""MIDI learn saves bindings into the user's config file without destroying comments or other keys."""

from __future__ import annotations

import argparse
import sys
import threading
from dataclasses import replace

import mido
import pytest
import yaml

from tests.control.midi.fakes import FakeEngine, midi_settings
from vibsynth.control.controller import Controller
from vibsynth.control.midi.adapter import learn
from vibsynth.control.midi.bindings import Binding, MidiSettings, parse_bindings
from vibsynth.control.midi.learn_store import save_learned_mapping
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import MidiServer
from vibsynth.settings.config import CONFIG_ENV_VAR, default_config_data, load_config, user_config_file
from vibsynth.settings.config_write import user_config_path

USER_CONFIG = """\
# my studio setup -- keep this comment
audio:
  rate: 44100   # the interface runs at 44.1 kHz
  block_size: 256

midi:
  # my keyboard
  port: Keystation
  release_ms: 300.0   # slow release
  mapping:
    intensity: [{cc: 11}]   # expression pedal
    balance: [{cc: 74}, {cc: 1}]

osc:
  port: 9999  # custom port
"""


def test_save_keeps_comments_and_other_keys(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG, encoding="utf-8")
    bindings = [
        Binding("intensity", cc=20),
        Binding("intensity", cc=11),
        Binding("balance", cc=74),
        Binding("balance", cc=2, channel=1, invert=True),
    ]
    save_learned_mapping(path, bindings)
    text = path.read_text(encoding="utf-8")
    for comment in (
        "# my studio setup -- keep this comment",
        "# the interface runs at 44.1 kHz",
        "# my keyboard",
        "# slow release",
        "# custom port",
    ):
        assert comment in text
    data = yaml.safe_load(text)
    assert data["audio"] == {"rate": 44100, "block_size": 256}
    assert data["osc"] == {"port": 9999}
    assert data["midi"]["port"] == "Keystation" and data["midi"]["release_ms"] == 300.0
    assert data["midi"]["mapping"] == {
        "intensity": [{"cc": 20}, {"cc": 11}],
        "balance": [{"cc": 74}, {"cc": 2, "channel": 2, "invert": True}],
    }
    # the saved file loads through the normal config path and parses back to the same bindings
    cfg = load_config(path)
    settings = midi_settings(cfg.settings, 1)
    assert [b for b in settings.bindings if b.cc is not None] == bindings


def test_learned_nrpn_is_written_as_msb_lsb(tmp_path):
    path = tmp_path / "config.yaml"
    save_learned_mapping(path, [Binding("balance", nrpn=3 * 128 + 4)])
    assert yaml.safe_load(path.read_text())["midi"]["mapping"]["balance"] == [{"nrpn": [3, 4]}]


def test_nrpn_shorthand_bindings_are_not_copied_into_the_mapping(tmp_path):
    """``midi.nrpn`` keeps its own bindings: learn writes an NRPN only when it was learned."""
    path = tmp_path / "config.yaml"
    shipped = parse_bindings({"intensity": [{"cc": 11}], "balance": [{"cc": 74}]}, None)
    assert sum(b.shorthand for b in shipped) == 2
    save_learned_mapping(path, shipped)
    data = yaml.safe_load(path.read_text())
    assert data["midi"]["mapping"] == {"intensity": [{"cc": 11}], "balance": [{"cc": 74}]}
    assert "nrpn" not in data["midi"]  # the default shorthand is left to apply by default
    reloaded = midi_settings(load_config(path, env={}).settings, 1).bindings
    assert set(reloaded) == set(shipped) and {b for b in reloaded if b.shorthand} == {
        Binding("intensity", nrpn=128),
        Binding("balance", nrpn=129),
    }


def test_learning_a_shorthand_nrpn_for_the_other_knob_reloads_as_learned(tmp_path):
    """The NRPN moves to the learned knob live, and the saved file reloads into the same bindings."""
    path = tmp_path / "config.yaml"
    path.write_text("midi:\n  mode: continuous  # faders\n", encoding="utf-8")
    shipped = parse_bindings({"intensity": [{"cc": 11}], "balance": [{"cc": 74}]}, None)
    mapper = MidiMapper(Controller(FakeEngine()), MidiSettings(mode="continuous", bindings=shipped))
    mapper.learn("balance", lambda binding, bindings: save_learned_mapping(path, bindings))
    for control, value in ((99, 1), (98, 0), (6, 100)):  # NRPN 1/0 (intensity's shorthand), data
        mapper.handle(mido.Message("control_change", control=control, value=value))
    live = set(mapper.bindings)
    assert Binding("balance", nrpn=128) in live and Binding("intensity", nrpn=128) not in live
    text = path.read_text()
    data = yaml.safe_load(text)
    assert data["midi"]["mapping"] == {"intensity": [{"cc": 11}], "balance": [{"nrpn": [1, 0]}, {"cc": 74}]}
    assert data["midi"]["nrpn"] == {"balance": [1, 1]}  # intensity's shorthand gave its NRPN away
    assert "# faders" in text and data["midi"]["mode"] == "continuous"
    assert set(midi_settings(load_config(path, env={}).settings, 1).bindings) == live


def test_save_creates_a_missing_file(tmp_path):
    path = tmp_path / "sub" / "config.yaml"
    save_learned_mapping(path, [Binding("balance", cc=2, channel=3)])
    assert yaml.safe_load(path.read_text())["midi"]["mapping"] == {
        "intensity": [],
        "balance": [{"cc": 2, "channel": 4}],
    }


def _unchanged_lines(text: str) -> list[str]:
    """The lines of a config file other than the two ``midi.mapping`` entries learn rewrites."""
    return [line for line in text.splitlines() if not line.lstrip().startswith(("intensity:", "balance:"))]


def test_server_learn_binds_and_saves(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG, encoding="utf-8")
    data = default_config_data()
    data["midi"]["mode"] = "continuous"
    controller = Controller(FakeEngine())
    mapper = MidiMapper(controller, midi_settings(data, 1))
    server = MidiServer(mapper, port="x", config_path=path)
    saved = threading.Event()
    original = server._save

    def save(p, b):
        original(p, b)
        saved.set()

    server._save = save  # type: ignore[method-assign]
    server.learn("intensity")
    assert mapper.learning == "intensity"
    server._feed(mido.Message("control_change", control=1, value=127))  # mod wheel -> intensity
    assert saved.wait(10.0)
    assert mapper.learning is None and [b.to_config() for b in server.learned] == [{"cc": 1}]
    assert controller.get("intensity") == 1.0  # the binding works at once
    text = path.read_text(encoding="utf-8")
    # the learned CC heads the knob's list (no channel key: it listens on every mapped MIDI
    # channel, like the shipped bindings); it is taken off balance, whose other entry stays
    assert yaml.safe_load(text)["midi"]["mapping"] == {
        "intensity": [{"cc": 1}, {"cc": 11}],
        "balance": [{"cc": 74}],
    }
    # every other line of the user's file, comments included, is there unchanged and in order
    assert _unchanged_lines(text) == _unchanged_lines(USER_CONFIG)
    assert "# expression pedal" in text  # the comment on the rewritten line too
    # the file loads through the normal config path into a mapper that responds to the learned CC
    cfg = load_config(path, env={})
    assert cfg.get("audio.rate") == 44100 and cfg.get("osc.port") == 9999 and cfg.get("midi.release_ms") == 300.0
    reloaded = Controller(FakeEngine())
    settings = midi_settings(cfg.settings, 1)
    settings = replace(settings, mode="continuous")
    fresh = MidiMapper(reloaded, settings)
    assert fresh.handle(mido.Message("control_change", control=1, value=64))
    assert reloaded.get("intensity") == pytest.approx(64 / 127)
    assert reloaded.get("balance") == 0.0  # CC 1 no longer moves balance
    assert fresh.handle(mido.Message("control_change", control=74, value=127))
    assert reloaded.get("balance") == pytest.approx(3.5)


def test_learn_path_follows_the_config_layer_rule(tmp_path, monkeypatch):
    """--config, else $VIBSYNTH_CONFIG, else the platform file: the file load_config reads."""
    explicit, from_env = tmp_path / "cli.yaml", tmp_path / "env.yaml"
    env = {CONFIG_ENV_VAR: str(from_env)}
    assert user_config_path(explicit, env=env) == explicit
    assert user_config_path(None, env=env) == from_env
    assert user_config_path(None, env={CONFIG_ENV_VAR: ""}) == user_config_file()
    assert user_config_path(None, env={}) == user_config_file()
    # the platform file is the config layer's, author folder and all (XDG on Linux)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    if sys.platform.startswith("linux"):
        assert user_config_path(None, env={}) == tmp_path / "xdg" / "vibsynth" / "config.yaml"
    # the same file the config layer reads
    for path in (explicit, from_env):
        path.write_text("osc:\n  port: 9999\n", encoding="utf-8")
    assert load_config(env=env).files[-1] == str(user_config_path(None, env=env))
    assert load_config(explicit, env=env).files[-1] == str(user_config_path(explicit, env=env))


def test_serve_learns_into_the_config_file_given_by_flag_or_environment(tmp_path, monkeypatch):
    """The MIDI adapter of ``vibsynth serve`` saves where --config / $VIBSYNTH_CONFIG point."""
    from vibsynth.control.midi import adapter

    monkeypatch.setattr(adapter.mido, "get_input_names", lambda: ["Keys A"])
    cfg = load_config(env={})
    args = argparse.Namespace(midi="keys", midi_virtual=False, no_midi=False, learn=None, config=None)

    monkeypatch.setenv(CONFIG_ENV_VAR, str(tmp_path / "env.yaml"))
    server = adapter.create(cfg.settings, args, Controller(FakeEngine()), None)
    assert server is not None and server.config_path == tmp_path / "env.yaml"

    args.config = tmp_path / "flag.yaml"  # --config wins over the environment
    server = adapter.create(cfg.settings, args, Controller(FakeEngine()), None)
    assert server is not None and server.config_path == tmp_path / "flag.yaml"

    monkeypatch.delenv(CONFIG_ENV_VAR)
    args.config = None
    server = adapter.create(cfg.settings, args, Controller(FakeEngine()), None)
    assert server is not None and server.config_path == user_config_file()


def test_module_learn_hook_without_server_returns_false():
    assert learn("balance") is False


# --------------------------------------------------------------------------- issue 12: one loader, one writer
BOMB = (
    "\n".join(
        ["a: &a [x,x,x,x,x,x,x,x,x]"]
        + [f"{b}: &{b} [" + ",".join([f"*{a}"] * 9) + "]" for a, b in zip("abcdefgh", "bcdefghi")]
    )
    + "\n"
)


def test_learn_refuses_a_bomb_config_and_leaves_it_untouched(tmp_path):
    from vibsynth.errors import ConfigError

    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG + BOMB, encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(ConfigError) as info:
        save_learned_mapping(path, [Binding("balance", cc=2)])
    # refused at the first alias it meets (line 17, column 8): nothing was expanded
    assert str(info.value).startswith(
        f"{path}:17:8: YAML alias '*a' (anchor '&a' on line 16): aliases are not allowed in a config file"
    )
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["config.yaml"]


def test_learn_goes_through_the_one_loader_and_the_one_writer(tmp_path, monkeypatch):
    import stat

    import vibsynth.formats.files as vfiles
    import vibsynth.formats.yamlio as vyaml

    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG, encoding="utf-8")
    path.chmod(0o640)
    calls: list[tuple[str, object]] = []
    real_load, real_write = vyaml.load_yaml, vfiles.atomic_write

    def load_yaml(*args, **kwargs):
        calls.append(("load", kwargs.get("round_trip")))
        return real_load(*args, **kwargs)

    def atomic_write(target, data):
        calls.append(("write", str(target)))
        return real_write(target, data)

    monkeypatch.setattr(vyaml, "load_yaml", load_yaml)
    monkeypatch.setattr(vfiles, "atomic_write", atomic_write)
    save_learned_mapping(path, [Binding("balance", cc=2)])
    assert calls == [("load", True), ("write", str(path))]
    assert stat.S_IMODE(path.stat().st_mode) == 0o640  # the user's mode is kept
    assert [p.name for p in tmp_path.iterdir()] == ["config.yaml"]  # no "config.yaml.tmp" left beside it
    assert yaml.safe_load(path.read_text())["midi"]["mapping"]["balance"] == [{"cc": 2}]


def test_learned_file_is_created_with_the_umask_mode(tmp_path):
    import os
    import stat

    old = os.umask(0o022)
    try:
        save_learned_mapping(tmp_path / "new" / "config.yaml", [Binding("intensity", cc=7)])
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new" / "config.yaml").stat().st_mode) == 0o644
