"""The typed ``follow:`` section: routes, the tracker's limits as its ranges, the cross-check with the channels."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from vibsynth.dsp.follow.params import GAIN_DB_LIMITS, GATE_DB_LIMITS, RANGE_DB_LIMITS, TIME_MS_LIMITS
from vibsynth.settings.models import bounds_of, default_of
from vibsynth.settings.models_config import VibsynthConfig


def test_the_ranges_are_the_trackers_own_limits():
    assert bounds_of("follow.gain_db") == GAIN_DB_LIMITS
    assert bounds_of("follow.gate_db") == GATE_DB_LIMITS
    assert bounds_of("follow.range_db") == RANGE_DB_LIMITS
    assert bounds_of("follow.attack_ms") == bounds_of("follow.release_ms") == TIME_MS_LIMITS
    assert default_of("follow.enabled") is False and default_of("follow.routes") == []


def test_routes_name_a_channel_or_a_source_and_their_inputs():
    settings = VibsynthConfig.model_validate(
        {
            "audio": {"channels": 2},
            "follow": {"routes": [{"channel": 2, "inputs": [1, 2], "gain_db": -3}, {"source": 4, "focus": "bass"}]},
        }
    )
    first, second = settings.follow.routes
    assert (first.channel, first.inputs, first.gain_db, first.mode) == (2, [1, 2], -3.0, None)
    assert (second.source, second.focus) == (4, "bass")


PAN = {"left": [0.0, 0.0], "right": [0.3, 0.0]}


def test_a_source_route_with_two_inputs_takes_a_pan_between_two_points():
    settings = VibsynthConfig.model_validate(
        {"follow": {"routes": [{"source": 2, "inputs": [1, 2], "pan": {**PAN, "right": [0.3, 0.1, 0.02]}}]}}
    )
    pan = settings.follow.routes[0].pan
    assert (pan.left, pan.right, pan.range_db) == ([0.0, 0.0], [0.3, 0.1, 0.02], 12.0)


def test_a_bad_pan_in_a_config_file_names_its_key_and_the_allowed_range(tmp_path):
    from vibsynth.errors import ConfigError
    from vibsynth.settings.config import check_config_file

    path = tmp_path / "user.yaml"
    path.write_text(
        "follow:\n  routes:\n    - {source: 1, inputs: [1, 2], pan: {left: [0, 0], right: [0.3, 0], range_db: 99}}\n"
    )
    with pytest.raises(
        ConfigError, match=r"user.yaml:3: follow.routes\[0\].pan.range_db = 99: outside the allowed range \[1, 60\] dB"
    ):
        check_config_file(path)


@pytest.mark.parametrize(
    ("follow", "message"),
    [
        ({"routes": [{"channel": 1, "source": 1}]}, "item 0: give either channel: N or source: K"),
        ({"routes": [{"inputs": [1]}]}, "item 0: give either channel: N or source: K"),
        ({"routes": [{"channel": 1}, {"channel": 1}]}, "item 1: channel 1 is followed by item 0 already"),
        ({"routes": [{"channel": 1, "inputs": [2, 2]}]}, "item 0: an input is listed twice"),
        ({"routes": [{"channel": 3}]}, "follow.routes[0].channel = 3: but audio.channels = 2"),
        ({"routes": [{"source": 17}]}, "less than or equal to 16"),
        ({"gain_db": 61}, "less than or equal to 60"),
        ({"mode": "noise"}, "'vibration' or 'audio'"),
        ({"on_loss": "stop"}, "'hold' or 'fade'"),
        ({"routes": [{"channel": 1, "inputs": [1, 2], "pan": PAN}]}, "item 0: pan moves a touch source"),
        ({"routes": [{"source": 1, "inputs": [1], "pan": PAN}]}, "item 0: pan needs exactly two inputs"),
        ({"routes": [{"source": 1, "pan": PAN}]}, "item 0: pan needs exactly two inputs"),
        ({"routes": [{"source": 1, "inputs": [1, 2], "pan": {**PAN, "range_db": 0.5}}]}, "greater than or equal to 1"),
        ({"routes": [{"source": 1, "inputs": [1, 2], "pan": {**PAN, "left": [0.0]}}]}, "at least 2 items"),
        ({"routes": [{"source": 1, "inputs": [1, 2], "pan": {**PAN, "right": [11.0, 0]}}]}, "less than or equal to 10"),
        ({"routes": [{"source": 1, "inputs": [1, 2], "pan": {"left": [0, 0]}}]}, "right"),
    ],
)
def test_bad_follow_settings_are_one_clear_error(follow, message):
    with pytest.raises(ValidationError, match=message.replace("[", r"\[").replace("]", r"\]")):
        VibsynthConfig.model_validate({"audio": {"channels": 2}, "follow": follow})
