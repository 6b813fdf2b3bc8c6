"""Stereo input pans a touch source: ``pan:`` of a source route (seeded noise, a real engine and mixer)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from tests.control.follow.fakes import FS
from tests.control.spatial.rig import make_mixer
from vibsynth.control import spatial
from vibsynth.control.follow.pan import StereoPan, pan_fraction
from vibsynth.dsp.follow import default_params
from vibsynth.dsp.follow.vibration import intensity_sos
from vibsynth.dsp.intensity import knob_to_level_db
from vibsynth.settings.models_config import ChannelPosition
from vibsynth.settings.models_follow import FollowPan

LEFT, RIGHT = [0.0, 0.0], [0.3, 0.0]
BLOCK = 128


def pan_rig(make_rig, *, range_db: float = 12.0, mode: str = "vibration"):
    """A rig whose route pans source 1 between two actuators 30 cm apart (linear roll-off, radius 30 cm)."""
    route = {"source": 1, "inputs": [1, 2], "pan": {"left": LEFT, "right": RIGHT, "range_db": range_db}}
    rig = make_rig(channels=2, inputs=2, follow={"mode": mode, "routes": [route]})
    positions = {1: ChannelPosition(x=LEFT[0], y=LEFT[1]), 2: ChannelPosition(x=RIGHT[0], y=RIGHT[1])}
    mixer = make_mixer(
        rig.controller, rig.follower.basis, positions=positions, clock=rig.clock, radius_m=0.3, glide_s=0.0
    )
    spatial.attach(rig.controller, mixer)
    rig.controller.set_knob("intensity", 0.0, source="osc")  # a channel no source reaches is silent
    return rig, mixer


def run(rig, mixer, x: np.ndarray) -> np.ndarray:
    """Feed ``x`` (n, 2) a block at a time: the follower, the mixer and the engine step in turn; the output."""
    out = []
    for i in range(0, len(x), BLOCK):
        rig.source.write(x[i : i + BLOCK])
        rig.follower.step()
        mixer.step()
        out.append(rig.engine.render(BLOCK))
        rig.clock.t += BLOCK / FS
    return np.concatenate(out)


def place(mixer) -> tuple[float, float, float]:
    return mixer.read(lambda table, t: table.view(0, t).target)


def noise(seconds: float, seed: int, rms: float = 0.01) -> np.ndarray:
    return rms * np.random.default_rng(seed).standard_normal(int(seconds * FS))


def band_db(y: np.ndarray) -> float:
    """The 80-200 Hz band level (dB re unit RMS) of one rendered channel."""
    band = signal.sosfilt(intensity_sos(FS), y.astype(np.float64))
    return 10 * math.log10(max(float(np.mean(band[int(0.1 * FS) :] ** 2)), 1e-30))


@pytest.mark.parametrize(("gains", "expected"), [((1, 0), LEFT), ((1, 1), [0.15, 0.0]), ((0, 1), RIGHT)])
def test_left_only_centred_and_right_only_noise_put_the_source_at_left_middle_right(make_rig, gains, expected):
    rig, mixer = pan_rig(make_rig)
    n = noise(0.6, seed=3)
    run(rig, mixer, np.stack([gains[0] * n, gains[1] * n], axis=1))
    assert place(mixer) == pytest.approx((*expected, 0.0), abs=1e-9)
    assert mixer.read(lambda table, t: table.view(0, t).on)  # a panned source appears where it is put
    (view,) = rig.follower.routes()
    assert view.label == "source1" and view.pan == pytest.approx([0.0, 0.5, 1.0][[(1, 0), (1, 1), (0, 1)].index(gains)])


def test_a_constant_power_pan_sweep_moves_the_source_monotonically_by_the_level_difference(make_rig):
    rig, mixer = pan_rig(make_rig, range_db=30.0)
    angles = np.linspace(0.0, math.pi / 2, 9)
    n = noise(0.3 * len(angles), seed=4)
    xs, seen = [], []
    for k, a in enumerate(angles):
        part = n[k * int(0.3 * FS) : (k + 1) * int(0.3 * FS)]
        run(rig, mixer, np.stack([math.cos(a) * part, math.sin(a) * part], axis=1))
        xs.append(place(mixer)[0])
        seen.append(rig.follower.routes()[0].pan)
    assert np.all(np.diff(xs) > 0), xs
    with np.errstate(divide="ignore"):
        difference = 20 * np.log10(np.cos(angles) / np.sin(angles))  # L - R of the same noise, dB
    expected = [pan_fraction(float(d), 30.0) for d in difference]
    assert seen == pytest.approx(expected, abs=1e-3)
    assert xs == pytest.approx([0.3 * u for u in expected], abs=0.3 * 6e-3)  # moved when it changed by 0.5 %


def test_independent_noise_of_equal_level_stays_near_the_middle(make_rig):
    """Two uncorrelated noises of one level: the 100 ms window's scatter is a few per cent of the span."""
    pan = StereoPan(FS, default_params("vibration"), FollowPan(left=LEFT, right=RIGHT))
    x = np.stack([noise(4.0, seed=5), noise(4.0, seed=6)], axis=1)
    fractions = [pan.process(x[i : i + BLOCK]) for i in range(0, len(x), BLOCK)][int(0.2 * FS / BLOCK) :]
    assert abs(float(np.median(fractions)) - 0.5) < 0.02
    assert float(np.percentile(np.abs(np.array(fractions) - 0.5), 95)) < 0.15


def test_the_rendered_channels_follow_the_move_by_the_layouts_roll_off(make_rig):
    """Left only, centred, right only: each actuator's 80-200 Hz output level is the source's level plus
    10 log10 of its linear roll-off weight (1 on the actuator, 0.5 half way, 0 at the radius).

    Levels are relative to the source's knob level; the on-actuator level (the small test bank's own
    calibration, about -2.5 dB at 16 kHz) is the reference the other positions are compared with."""
    rig, mixer = pan_rig(make_rig)
    levels = {}
    for name, (gl, gr) in {"left": (1, 0), "middle": (1, 1), "right": (0, 1)}.items():
        n = noise(1.2, seed=7)
        y = run(rig, mixer, np.stack([gl * n, gr * n], axis=1))[int(0.4 * FS) :]
        source_db = knob_to_level_db(mixer.read(lambda table, t: table.view(0, t).intensity))
        levels[name] = (band_db(y[:, 0]) - source_db, band_db(y[:, 1]) - source_db)
    on_actuator = levels["left"][0]
    half = on_actuator + 10 * math.log10(0.5)
    assert on_actuator == pytest.approx(0.0, abs=3.0) and levels["left"][1] < -40
    assert levels["middle"] == pytest.approx((half, half), abs=1.0)
    assert levels["right"][1] == pytest.approx(on_actuator, abs=1.0) and levels["right"][0] < -40


def test_the_pan_holds_through_silence_and_follows_audio_modes_k_weighted_levels(make_rig):
    rig, mixer = pan_rig(make_rig, mode="audio")
    n = noise(0.6, seed=8, rms=0.1)
    run(rig, mixer, np.stack([n, 0.5 * n], axis=1))  # L - R = 6 dB -> a quarter of the way
    assert rig.follower.routes()[0].pan == pytest.approx(0.25, abs=1e-3)
    run(rig, mixer, np.zeros((int(0.5 * FS), 2)))
    assert place(mixer)[0] == pytest.approx(0.3 * 0.25, abs=0.3 * 6e-3)
