"""MIDI learn saves bindings into the user's config file without destroying comments or other keys."""

from __future__ import annotations

import threading

import mido
import yaml

from vibsynth.control.controller import Controller
from vibsynth.control.midi.adapter import learn
from vibsynth.control.midi.bindings import Binding, MidiSettings
from vibsynth.control.midi.learn_store import save_learned_mapping
from vibsynth.control.midi.mapper import MidiMapper
from vibsynth.control.midi.server import MidiServer
from vibsynth.settings.config import default_config_data, load_config

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


class FakeEngine:
    channels, fs = 1, 48000.0

    def __init__(self) -> None:
        self.n = 0

    def submit(self, command) -> int:
        self.n += 1
        return self.n

    applied_seq = property(lambda self: self.n)
    frame_position = property(lambda self: 0)


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
    settings = MidiSettings.from_config(cfg.data, 1)
    assert [b for b in settings.bindings if b.cc is not None] == bindings


def test_learned_nrpn_is_written_as_msb_lsb(tmp_path):
    path = tmp_path / "config.yaml"
    save_learned_mapping(path, [Binding("balance", nrpn=3 * 128 + 4)])
    assert yaml.safe_load(path.read_text())["midi"]["mapping"]["balance"] == [{"nrpn": [3, 4]}]


def test_save_creates_a_missing_file(tmp_path):
    path = tmp_path / "sub" / "config.yaml"
    save_learned_mapping(path, [Binding("balance", cc=2, channel=3)])
    assert yaml.safe_load(path.read_text())["midi"]["mapping"] == {
        "intensity": [],
        "balance": [{"cc": 2, "channel": 4}],
    }


def test_server_learn_binds_and_saves(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG, encoding="utf-8")
    data = default_config_data()
    data["midi"]["mode"] = "continuous"
    controller = Controller(FakeEngine())
    mapper = MidiMapper(controller, MidiSettings.from_config(data, 1))
    server = MidiServer(mapper, port="x", config_path=path)
    saved = threading.Event()
    original = server._save

    def save(p, b):
        original(p, b)
        saved.set()

    server._save = save  # type: ignore[method-assign]
    server.learn("intensity")
    server._feed(mido.Message("control_change", control=1, value=127))  # mod wheel -> intensity
    assert saved.wait(10.0)
    assert controller.get("intensity") == 1.0
    text = path.read_text(encoding="utf-8")
    assert "# expression pedal" not in text or "cc: 1" in text
    mapping = yaml.safe_load(text)["midi"]["mapping"]
    assert mapping["intensity"][0] == {"cc": 1}
    assert {"cc": 1} not in mapping["balance"]
    assert "# my studio setup -- keep this comment" in text and "# custom port" in text


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
    import time

    import pytest

    from vibsynth.errors import ConfigError

    path = tmp_path / "config.yaml"
    path.write_text(USER_CONFIG + BOMB, encoding="utf-8")
    before = path.read_bytes()
    started = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        save_learned_mapping(path, [Binding("balance", cc=2)])
    assert time.perf_counter() - started < 0.5
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
