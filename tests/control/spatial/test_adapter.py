"""The sources' adapter: a mixer only with a layout, built from the config; serve --layout."""

from __future__ import annotations

import argparse

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.cli.serve import _settings
from vibsynth.control import ADAPTER_MODULES, spatial
from vibsynth.control.spatial import adapter
from vibsynth.settings.config import ENV_VARS, load_config


@pytest.fixture(autouse=True)
def isolated(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    for var in list(ENV_VARS) + ["VIBSYNTH_CONFIG"]:
        monkeypatch.delenv(var, raising=False)


def test_no_layout_no_mixer():
    config = load_config(env={}, user_file=False)
    assert adapter.create(config.settings, None, make_controller(channels=2)) is None


def test_the_mixer_takes_the_config(basis):
    config = load_config(
        overrides={
            "audio.channels": 6,
            "layout": "glove",
            "sources": {"radius": 0.03, "rolloff": "phantom", "update_ms": 20, "glide_ms": 0, "speed": True},
            "knobs": {"ceiling_db": -30.0, "range_db": 50.0, "balance_min": -2.0, "balance_max": 2.0},
        },
        env={},
        user_file=False,
    )
    ctl = make_controller(channels=6)
    mixer = adapter.create(config.settings, None, ctl)
    assert mixer.layout.name == "glove" and mixer.layout.channels == (0, 1, 2, 3, 4, 5)
    assert mixer.update_s == pytest.approx(0.02) and (mixer.ceiling_db, mixer.range_db) == (-30.0, 50.0)
    defaults = mixer.table.defaults
    assert (defaults.radius_m, defaults.rolloff, defaults.glide_s, defaults.speed) == (0.03, "phantom", 0.0, True)
    assert defaults.radius_max_m == 10.0
    assert mixer.describe() == "sources: 16 on layout glove (6 actuators), mixed every 20 ms"
    mixer.start()
    try:
        assert spatial.mixer_of(ctl) is mixer
    finally:
        mixer.stop()
    assert spatial.mixer_of(ctl) is None


def test_serve_has_a_layout_flag_that_sets_the_config():
    assert ADAPTER_MODULES[0] == "vibsynth.control.spatial.adapter"  # the mixer exists before OSC listens
    parser = argparse.ArgumentParser()
    adapter.add_arguments(parser)
    args = parser.parse_args(["--layout", "wristband"])
    args.channels, args.output, args.device, args.wav, args.config, args.config_set = 8, "null", None, None, None, []
    assert _settings(args).layout == "wristband"
    args.layout = None
    assert _settings(args).layout is None  # the flag set it, not a file
    with pytest.raises(SystemExit):
        parser.parse_args(["--layout", "../etc"])
