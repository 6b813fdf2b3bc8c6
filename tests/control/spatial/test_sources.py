"""The sources' state: validation at the edge, position glides, speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.control.osc.fakes import FakePreset
from vibsynth.control.controller import KnobLimits
from vibsynth.control.spatial.sources import SourceDefaults, SourceTable
from vibsynth.errors import ParameterError


@pytest.fixture
def table():
    return SourceTable(SourceDefaults(glide_s=0.02, speed_window_s=0.1, limits=KnobLimits(-2.0, 2.0)))


@pytest.mark.parametrize(
    "values, fragment",
    [
        ((math.nan, 0.0), "x (m) must be a finite number, got nan"),
        ((0.0, math.inf), "y (m) must be a finite number, got inf"),
        ((0.0, 0.0, -math.inf), "z (m) must be a finite number, got -inf"),
        ((11.0, 0.0), "x (m) 11 is outside the allowed range [-10, 10]"),
        ((0.0,), "a position has 2 or 3 coordinates"),
        ((0.0, 0.0, 0.0, 0.0), "a position has 2 or 3 coordinates"),
    ],
)
def test_bad_positions_are_refused(values, fragment):
    with pytest.raises(ParameterError) as info:
        SourceTable.check_position(values)
    assert fragment in str(info.value)


def test_positions_take_two_or_three_coordinates():
    assert SourceTable.check_position((0.1, -0.2)) == (0.1, -0.2, 0.0)
    assert SourceTable.check_position((0.1, -0.2, 0.3)) == (0.1, -0.2, 0.3)


@pytest.mark.parametrize("radius", [0.0, -0.1, 10.5, 1e30, math.nan, math.inf])
def test_a_radius_must_lie_in_its_range(table, radius):
    with pytest.raises(ParameterError, match="radius"):
        table.check_radius(radius)
    assert table.check_radius(10.0) == 10.0


def test_knob_values_use_the_live_ranges(table):
    assert table.check_intensity(1.0) == 1.0
    with pytest.raises(ParameterError, match=r"intensity 1.5 is outside the allowed range \[0, 1\]"):
        table.check_intensity(1.5)
    with pytest.raises(ParameterError, match=r"balance 3 is outside the allowed range \[-2, 2\]"):
        table.check_balance(3.0)


def test_unknown_sources_and_roll_offs(table):
    with pytest.raises(ParameterError, match=r"source 17 does not exist \(sources are 1..16\)"):
        table.set_radius(16, 0.1)
    with pytest.raises(ParameterError, match="unknown roll-off 'cubic'"):
        table.set_rolloff(0, "cubic")
    assert table.view(0, 0.0).rolloff == "smooth"


def test_a_position_glides_from_where_the_source_is(table):
    table.set_on(0, True, 0.0)
    table.set_position(0, (0.1, 0.0, 0.0), 1.0)
    assert table.view(0, 1.01).position == pytest.approx((0.05, 0.0, 0.0))
    assert table.view(0, 1.01).moving
    table.set_position(0, (0.1, 0.2, 0.0), 1.01)  # mid-glide: from (0.05, 0, 0)
    assert table.view(0, 1.02).position == pytest.approx((0.075, 0.1, 0.0))
    assert table.view(0, 1.03).position == (0.1, 0.2, 0.0) and not table.view(0, 1.03).moving
    assert table.view(0, 1.03).target == (0.1, 0.2, 0.0)


def test_an_off_source_jumps_and_appears_where_it_was_sent(table):
    table.set_position(1, (0.3, 0.0, 0.0), 5.0)
    assert table.view(1, 5.0).position == (0.3, 0.0, 0.0)
    table.set_on(1, True, 6.0)
    assert table.view(1, 6.0).position == (0.3, 0.0, 0.0) and not table.view(1, 6.0).moving


def test_speed_is_the_path_over_the_window(table, rng):
    table.set_speed(2, True)
    table.set_on(2, True, 0.0)
    points = np.cumsum(rng.normal(0, 0.002, (30, 3)), axis=0)
    for k, p in enumerate(points):
        table.set_position(2, tuple(p), 0.01 * k)
    now = 0.29
    recent = points[-11:]  # the positions of the last 100 ms (0.19 .. 0.29)
    path = np.sum(np.linalg.norm(np.diff(recent, axis=0), axis=1))
    assert table.view(2, now).speed_mm_s == pytest.approx(1000 * path / 0.1)
    assert table.view(2, 0.5).speed_mm_s == 0.0  # nothing new for longer than the window: at rest
    assert not table.view(2, 0.5).moving


def test_a_preset_gives_its_knobs_clamped_to_the_live_range(table):
    table.set_preset(3, FakePreset("grit", 0.6, 3.0))
    view = table.view(3, 0.0)
    assert (view.intensity, view.balance, view.preset) == (0.6, 2.0, "grit")
    table.set_texture(3, balance=1.0)
    assert table.view(3, 0.0).preset is None
    with pytest.raises(ParameterError, match="no preset library"):
        table.resolve_preset("grit")


def test_panic_turns_every_source_off_and_keeps_the_rest(table):
    for k in range(16):
        table.set_on(k, True, 0.0)
    table.set_texture(4, 0.5, 1.0)
    table.all_off()
    assert not any(v.on for v in table.views(0.0))
    assert table.view(4, 0.0).intensity == 0.5
