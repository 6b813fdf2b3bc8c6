"""The typed ``vrchat:`` section: one target per parameter, positions only for sources, names unique."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.models_vrchat import Vrchat


def test_the_issue_example_is_valid():
    section = Vrchat(
        enabled=True,
        parameters=[
            {"name": "ChestL", "source": 1, "at": [-0.1, 0.25], "preset": "velvet", "drive": "level"},
            {"name": "ChestR", "source": 2, "at": [0.1, 0.25], "preset": "gravel", "drive": "velocity"},
            {"name": "Slap", "clip": "impact"},
            {"name": "Go/Float", "channel": 2, "preset": "towel"},
            {"name": "Tail_Angle", "source": 3, "moving": [[0, 0], [0.2, 0.1, 0.05]]},
        ],
    )
    assert [p.name for p in section.parameters] == ["ChestL", "ChestR", "Slap", "Go/Float", "Tail_Angle"]


@pytest.mark.parametrize(
    "entry, fragment",
    [
        ({"name": "A", "source": 1}, "at a point"),
        ({"name": "A", "source": 1, "at": [0, 0], "moving": [[0, 0], [1, 0]]}, "at a point"),
        ({"name": "A", "source": 1, "clip": "impact", "at": [0, 0]}, "drives one thing"),
        ({"name": "A"}, "drives nothing"),
        ({"name": "A", "channel": 1, "at": [0, 0]}, "places a source"),
        ({"name": "A", "clip": "impact", "drive": "velocity"}, "needs a source or a channel"),
        ({"name": "A", "preset": "silk", "drive": "velocity"}, "needs a source or a channel"),
        ({"name": "A B", "channel": 1}, "name"),
        ({"name": "A*", "channel": 1}, "name"),
        ({"name": "A", "source": 17, "at": [0, 0]}, "source"),
        ({"name": "A", "source": 1, "at": [0, 11]}, "at"),
        ({"name": "A", "channel": 1, "drive": "speed"}, "drive"),
    ],
)
def test_bad_entries_say_what_is_wrong(entry, fragment):
    with pytest.raises(ValidationError, match=fragment):
        Vrchat(parameters=[entry])


def test_a_name_is_mapped_once():
    with pytest.raises(ValidationError, match="mapped by item 0"):
        Vrchat(parameters=[{"name": "A", "channel": 1}, {"name": "A", "clip": "impact"}])


def test_channels_and_sources_are_checked_against_the_rest_of_the_config():
    with pytest.raises(ValidationError, match="audio.channels = 2"):
        VibsynthConfig(audio={"channels": 2}, vrchat={"parameters": [{"name": "A", "channel": 3}]})
    with pytest.raises(ValidationError, match="sources need a layout"):
        VibsynthConfig(vrchat={"enabled": True, "parameters": [{"name": "A", "source": 1, "at": [0, 0]}]})
