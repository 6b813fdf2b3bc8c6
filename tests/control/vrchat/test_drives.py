"""The level and velocity drives on seeded signals: rate -> amount, the fade after the last change, edges."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.control.vrchat.drives import MIN_DT_S, Velocity, crossed, level_amount


def test_level_is_the_value_clipped():
    rng = np.random.default_rng(23)
    values = rng.uniform(-2, 2, 200)
    assert [level_amount(v) for v in values] == pytest.approx(np.clip(values, 0, 1))


def test_velocity_amount_follows_the_rate_of_change():
    rng = np.random.default_rng(7)
    for speed in rng.uniform(0.1, 3.9, 20):  # units per second, below full (4)
        drive = Velocity(full=4.0, fade_s=0.3)
        t, v = 0.0, 0.0
        for _ in range(30):  # a proximity rising steadily at 90 Hz, as VRChat sends it
            drive.change(v, t)
            t, v = t + 1 / 90, v + speed / 90
        assert drive.amount(drive.time) == pytest.approx(speed / 4.0, rel=1e-6)


def test_faster_is_more_and_the_amount_saturates():
    slow, fast, faster = (Velocity(full=2.0, fade_s=0.3) for _ in range(3))
    for drive, step in ((slow, 0.005), (fast, 0.015), (faster, 0.2)):
        drive.change(0.0, 0.0)
        drive.change(step, 0.01)
    assert slow.peak < fast.peak < faster.peak == 1.0


def test_velocity_fades_linearly_once_the_parameter_stops_changing():
    drive = Velocity(full=1.0, fade_s=0.25)
    drive.change(0.2, 1.0)
    drive.change(0.25, 1.1)  # 0.5 units/s: amount 0.5
    assert drive.amount(1.1) == pytest.approx(0.5)
    assert drive.amount(1.1 + 0.125) == pytest.approx(0.25)
    assert drive.amount(1.1 + 0.25) == 0.0 and not drive.active(1.1 + 0.25)
    drive.change(0.25, 1.2)  # the same value again is no change: the fade goes on
    assert drive.amount(1.2) == pytest.approx(0.5 * (1 - 0.1 / 0.25))


def test_a_first_value_starts_nothing_and_a_burst_counts_as_one_frame():
    drive = Velocity(full=10.0, fade_s=0.3)
    drive.change(0.7, 5.0)
    assert drive.amount(5.0) == 0.0
    drive.change(0.8, 5.0)  # delivered together: measured over MIN_DT_S
    assert drive.peak == pytest.approx(min(0.1 / MIN_DT_S / 10.0, 1.0))
    drive.reset()
    assert drive.value is None and drive.amount(5.0) == 0.0


def test_crossing_is_a_rising_edge_only():
    assert crossed(0.0, 1.0, 0.0)  # F -> T
    assert not crossed(1.0, 1.0, 0.0) and not crossed(1.0, 0.0, 0.0)  # held, released
    assert crossed(0.4, 0.6, 0.5) and not crossed(0.6, 0.4, 0.5) and not crossed(0.6, 0.7, 0.5)
