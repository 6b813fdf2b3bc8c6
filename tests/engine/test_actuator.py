"""A measured (absolute) actuator profile's boost limit counts from its own band level."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.engine.actuator import ActuatorResponse

# A voice coil measured through a sensor chain 20 dB down: -20 dB in the band, -50 dB at 10 Hz.
POINTS = [[10, -50.0], [40, -25.0], [80, -20.0], [200, -20.0], [1000, -20.0]]


def test_absolute_profile_boost_is_relative_to_its_band_level():
    absolute = ActuatorResponse.from_points(POINTS, max_boost_db=12, absolute=True)
    assert absolute.reference_db() == pytest.approx(-20.0, abs=0.15)  # the band-pass skirts see 40-80 Hz
    eq = 20 * np.log10(absolute.inverse_gain([10.0, 40.0, 140.0]))
    # in band the whole 20 dB are made up; at 10 Hz the shape is boosted 12 dB beyond that
    np.testing.assert_allclose(eq, [12.0 - absolute.reference_db(), 25.0, 20.0], atol=0.01)


def test_a_relative_profile_keeps_the_absolute_limit_and_the_flag_is_in_the_cache_key():
    relative = ActuatorResponse.from_points(POINTS, max_boost_db=12)
    assert relative.reference_db() == 0.0
    np.testing.assert_allclose(20 * np.log10(relative.inverse_gain([10.0, 140.0])), [12.0, 12.0])
    assert relative.key() != ActuatorResponse.from_points(POINTS, max_boost_db=12, absolute=True).key()


def test_a_measured_voice_coil_30_db_down_at_10_hz_is_covered_with_the_raised_limit():
    from vibsynth.limits import ACTUATOR_BOOST_MAX_DB

    coil = ActuatorResponse.from_points([[10, -30.0], [65, 9.5], [1000, 0.0]], max_boost_db=40, absolute=True)
    assert ACTUATOR_BOOST_MAX_DB >= 40
    felt = 20 * np.log10(coil.inverse_gain([10.0])) + coil.response_db([10.0])
    in_band = 20 * np.log10(coil.inverse_gain([140.0])) + coil.response_db([140.0])
    assert felt[0] == pytest.approx(in_band[0], abs=0.01)  # flat felt response down to 10 Hz
