"""``vibsynth serve`` builds the typed settings once: no part validates the config again."""

from __future__ import annotations

import pytest

from vibsynth.cli import main
from vibsynth.settings.models_config import VibsynthConfig


@pytest.fixture
def full_validations(monkeypatch):
    """Count whole-config validations (the per-layer checks of the loader, without the rules between keys, aside)."""
    calls: list[str] = []
    original = VibsynthConfig.model_validate

    def counting(cls, obj, **kwargs):
        context = kwargs.get("context") or {}
        if context.get("cross_checks", True):
            calls.append("full")
        return original(obj, **kwargs)

    monkeypatch.setattr(VibsynthConfig, "model_validate", classmethod(counting))
    return calls


@pytest.fixture
def settings_of_calls(monkeypatch):
    """Count entries to ``settings.typed.settings_of``, under whatever name a module imported it."""
    import sys

    from vibsynth.settings import typed

    calls: list[str] = []
    original = typed.settings_of

    def counting(config):
        caller = sys._getframe(1)
        calls.append(f"{caller.f_globals['__name__']}.{caller.f_code.co_name}")
        return original(config)

    monkeypatch.setattr(typed, "settings_of", counting)  # modules imported from now on bind this one
    for name, module in list(sys.modules.items()):
        if name.startswith("vibsynth.") and getattr(module, "settings_of", None) is original:
            monkeypatch.setattr(module, "settings_of", counting)
    return calls


def test_one_serve_start_validates_the_config_once(tmp_path, monkeypatch, capsys, full_validations, settings_of_calls):
    """Every part (engine, outputs, OSC, MIDI, clips, sources, studio, lab) gets its typed section.

    Before, each re-made the model from the dict with ``settings_of``: 8 validations a start; then
    the layouts and actuator profiles still took the whole config and passed it through
    ``settings_of`` (10 entries a start, each returning the model it was given). The loader builds
    the model; nothing after it enters ``settings_of``.
    """
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    config = tmp_path / "config.yaml"
    config.write_text(
        "audio:\n  rate: 8000\n  channels: 8\n"
        "bank:\n  cache_dir: ''\n  loop_seconds: 0.5\n  levels: 3\n"
        "osc:\n  port: 0\nstudio:\n  port: 0\nlayout: wristband\n"
        "midi_clips:\n  notes: [{note: 38, clip: rain}]\n",
        encoding="utf-8",
    )
    assert main(["serve", "--config", str(config), "--output", "null", "--seconds", "0.1", "--no-midi"]) == 0
    out = capsys.readouterr().out
    assert "OSC on udp://" in out and "studio: http://" in out and "clips:" in out  # every part started
    assert full_validations == ["full"]
    assert settings_of_calls == []
    from vibsynth.settings.config import Config

    assert Config(data={}).settings.audio.channels == 1 and settings_of_calls == [
        "vibsynth.settings.config.settings"
    ]  # it counts


def test_serve_takes_the_typed_settings_and_validates_nothing(tmp_path, monkeypatch, capsys, full_validations):
    import argparse

    from vibsynth.app.service import serve
    from vibsynth.settings.config import load_config

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    overrides = {"audio.rate": 8000, "bank": {"cache_dir": "", "loop_seconds": 0.5, "levels": 3}, "osc.port": 0}
    settings = load_config(overrides={**overrides, "studio.enabled": False}, env={}, user_file=False).settings
    full_validations.clear()
    args = argparse.Namespace(seconds=0.05, no_midi=True, intensity=0.5)
    assert serve(settings, args) == 0
    assert "serving 1 channel(s) on null output" in capsys.readouterr().out
    assert full_validations == []


def _profile(folder, name, points, *, weighting=None):
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f"name: {name}", "absolute: true", "rate: 16000", f"response: {points}"]
    if weighting is not None:
        lines.append(f"weighting: {weighting}")
    (folder / f"{name}.yaml").write_text("\n".join(lines) + "\n")


def test_build_engine_trims_the_channels_with_their_own_profiles(tmp_path, monkeypatch):
    """Layout profiles and actuator.channel_profiles reach the engine: a bank for the mean, each channel trimmed."""
    import numpy as np

    from vibsynth.app.service import build_engine
    from vibsynth.settings.config import load_config

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    folder = tmp_path / "cfg" / "vibsynth" / "actuators"
    _profile(folder, "low", [[10, -6], [60, 6], [1000, -6]])
    _profile(folder, "high", [[10, -20], [300, 4], [1000, 4]])
    small = {"rate": 16000, "channels": 3}
    bank = {"levels": 9, "loop_seconds": 1.0, "cache_dir": ""}
    layout = {1: {"x": 0, "y": 0, "profile": "low"}, 2: {"x": 1, "y": 0, "profile": "high"}, 3: {"x": 2, "y": 0}}
    overrides = {"audio": small, "bank": bank, "layout": layout, "actuator": {"profile": "low", "max_boost_db": 40}}
    engine = build_engine(load_config(overrides=overrides, user_file=False).settings)
    engine.render(64)
    trims = engine.trim_values()
    # channels 1 and 3 play 'low', channel 2 'high': the bank is their mean, all three trimmed, 1 and 3 alike
    assert trims[0] == trims[2] and trims[0] != (0.0, 1.0) and trims[1] != trims[0]
    assert np.sign(trims[1][0]) != np.sign(trims[0][0])  # one brighter, one darker than the mean
    assert engine.bank.key["actuator"][0] != [[10, -6], [60, 6], [1000, -6]]
    overrides["actuator"]["channel_profiles"] = ["high", "high", "high"]  # wins over the layout's
    engine = build_engine(load_config(overrides=overrides, user_file=False).settings)
    engine.render(64)
    assert engine.trim_values() == [(0.0, 1.0)] * 3  # one response for all: the bank is built for it


def test_a_calibrated_profile_sets_what_the_bank_s_level_means(tmp_path, monkeypatch):
    from vibsynth.app.service import build_engine
    from vibsynth.settings.config import load_config

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    folder = tmp_path / "cfg" / "vibsynth" / "actuators"
    _profile(folder, "cal", [[10, -10], [100, 0], [1000, 0]], weighting=[[10, -30], [150, 0], [1000, -30]])
    _profile(folder, "plain", [[10, -10], [100, 0], [1000, 0]])
    bank = {"levels": 9, "loop_seconds": 1.0, "cache_dir": ""}
    keys = {}
    for name in ("cal", "plain"):
        overrides = {"audio": {"rate": 16000}, "bank": bank, "actuator": {"profile": name}}
        keys[name] = build_engine(load_config(overrides=overrides, user_file=False).settings).bank.key
    assert keys["cal"]["intensity"][0] == "weighting" and "intensity" not in keys["plain"]


def test_the_osc_server_binds_first_and_answers_last(tmp_path, monkeypatch, capsys):
    """A client's first ``/status`` already lists every part: the OSC port is bound before OSCQuery
    (whose HOST_INFO names it) and VRChat need it, and answered only once they, the studio and the
    output run (before, a /status sent during start-up lacked their keys)."""
    from vibsynth.control.osc.server import OscServer
    from vibsynth.control.oscquery.adapter import OscQueryService
    from vibsynth.control.studio.server import StudioServer
    from vibsynth.control.vrchat.adapter import VrchatService
    from vibsynth.engine.outputs import NullOutput

    order: list[str] = []
    for cls, method in (
        (OscServer, "bind"),
        (OscServer, "start"),
        (OscQueryService, "start"),
        (VrchatService, "start"),
        (StudioServer, "start"),
        (NullOutput, "start"),
    ):
        original = getattr(cls, method)

        def wrapped(self, *args, _original=original, _name=f"{cls.__name__}.{method}", **kwargs):
            order.append(_name)
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(cls, method, wrapped)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    config = tmp_path / "config.yaml"
    config.write_text(
        "audio:\n  rate: 8000\n  channels: 2\nbank:\n  cache_dir: ''\n  loop_seconds: 0.5\n  levels: 3\n"
        "osc:\n  port: 0\nstudio:\n  port: 0\ndiscovery:\n  oscquery_port: 0\n"
        "vrchat:\n  enabled: true\n  listen_port: 0\n  parameters: [{name: Hug, channel: 2}]\n",
        encoding="utf-8",
    )
    assert main(["serve", "--config", str(config), "--output", "null", "--seconds", "0.1", "--no-midi"]) == 0
    answered = order.index("OscServer.start")
    assert order[0] == "OscServer.bind", order
    assert {"OscQueryService.start", "VrchatService.start", "StudioServer.start", "NullOutput.start"} <= set(
        order[:answered]
    ), order
    assert "VRChat: 1 avatar parameter(s)" in capsys.readouterr().out
