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


def test_one_serve_start_validates_the_config_once(tmp_path, monkeypatch, capsys, full_validations):
    """Every part (engine, outputs, OSC, MIDI, clips, sources, studio, lab) gets its typed section.

    Before, each re-made the model from the dict with ``settings_of``: 8 validations a start.
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
