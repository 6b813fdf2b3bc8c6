"""The config model reads no files: the loader hands it the checks of the files a config names."""

from __future__ import annotations

import pytest

from vibsynth.errors import ConfigError
from vibsynth.settings.actuators import profile_problem
from vibsynth.settings.config import load_config
from vibsynth.settings.layouts import layout_problem
from vibsynth.settings.models_config import FILE_CHECKS, VibsynthConfig
from vibsynth.settings.typed import settings_of


def test_the_model_alone_looks_up_no_named_file():
    model = VibsynthConfig.model_validate({"layout": "no-such-layout", "actuator": {"profile": "no-such-coil"}})
    assert model.layout == "no-such-layout" and model.actuator.profile == "no-such-coil"
    assert settings_of({"layout": "no-such-layout"}).layout == "no-such-layout"  # typed settings of plain data


def test_the_model_runs_the_file_checks_it_is_handed():
    seen = []

    def check(config):
        seen.append(config.layout)
        return None

    VibsynthConfig.model_validate({"layout": "glove"}, context={FILE_CHECKS: (check,)})
    assert seen == ["glove"]
    with pytest.raises(ValueError, match="layout glove places channel 6 but audio.channels = 2"):
        VibsynthConfig.model_validate(
            {"layout": "glove", "audio": {"channels": 2}}, context={FILE_CHECKS: (layout_problem,)}
        )


def test_the_loader_checks_the_named_files():
    with pytest.raises(ConfigError, match=r"layout = 'glov': no such layout; did you mean glove\?"):
        load_config(overrides={"layout": "glov", "audio.channels": 6}, user_file=False, env={})
    with pytest.raises(ConfigError, match="actuator.profile = 'no-such-coil': no such profile"):
        load_config(overrides={"actuator.profile": "no-such-coil"}, user_file=False, env={})
    assert (
        load_config(overrides={"layout": "glove", "audio.channels": 6}, user_file=False, env={}).settings.layout
        == "glove"
    )


def test_the_file_checks_pass_what_needs_no_file():
    inline = VibsynthConfig.model_validate({"layout": {1: {"x": 0, "y": 0}}})
    explicit = VibsynthConfig.model_validate({"actuator": {"profile": "no-such-coil", "response": [[40, 0], [50, 3]]}})
    assert layout_problem(inline) is None and profile_problem(explicit) is None  # nothing named to read


def test_an_inline_layout_beyond_the_channels_is_the_model_s_own_rule():
    with pytest.raises(ValueError, match="layout: channel 3 is placed but audio.channels = 2"):
        VibsynthConfig.model_validate({"layout": {3: {"x": 0, "y": 0}}, "audio": {"channels": 2}})
