"""One setting written into a config file: comments and other keys kept, bad files refused untouched."""

from __future__ import annotations

import pytest

from vibsynth.errors import ConfigError
from vibsynth.settings.config import load_config
from vibsynth.settings.config_write import write_config_key


def test_a_key_is_set_and_everything_else_stays(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text("# rig A\naudio:\n  channels: 3   # three coils\nactuator:\n  profile: flat\n")
    write_config_key(path, "actuator.channel_profiles", ["flat", None, "hapcoil-example"])
    text = path.read_text()
    assert text.startswith("# rig A\n") and "channels: 3   # three coils" in text and "profile: flat" in text
    assert "channel_profiles: [flat, null, hapcoil-example]" in text
    write_config_key(path, "actuator.channel_profiles", ["flat", "flat", None])  # replaced, not added twice
    assert path.read_text().count("channel_profiles") == 1
    assert load_config(path, user_file=False).settings.actuator.channel_profiles == ["flat", "flat", None]


def test_a_missing_file_and_missing_sections_are_made(tmp_path):
    path = tmp_path / "new" / "config.yaml"
    write_config_key(path, "actuator.channel_profiles", ["hapcoil-example"])
    assert load_config(path, user_file=False).settings.actuator.channel_profiles == ["hapcoil-example"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("actuator: [1, 2]\n", "actuator must be a mapping"),
        ("- a\n- b\n", "must be a mapping of sections"),
        ("a: &x [1]\nb: *x\n", "alias"),
        ("audio: {channels: [\n", "config.yaml:"),
    ],
)
def test_a_file_that_cannot_hold_the_key_is_refused_and_left_alone(tmp_path, text, message):
    path = tmp_path / "config.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        write_config_key(path, "actuator.channel_profiles", ["a"])
    assert "\n" not in str(info.value).strip() and path.read_text() == text
