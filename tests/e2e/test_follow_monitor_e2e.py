"""End to end: ``serve --follow monitor`` on JACK follows what the system plays.

serve's input ports are patched by its monitor worker to whatever feeds ``system:playback_N``
(excluding serve's own outputs). A JACK client started *after* serve plays a 140 Hz tone into
the playback ports; serve's tracked level and its actuator output's 80-200 Hz level rise above
their silent baseline, measured in the same test before the tone.

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_follow_monitor_e2e.py -q -s``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy import signal as sps

from tests.e2e.jackutil import REALTIME, JackCapture, JackPlayer
from tests.e2e.test_follow_e2e import FS, Served
from vibsynth.dsp.follow.vibration import intensity_sos

pytestmark = [pytest.mark.e2e, REALTIME]

TONE_DB = -50.0  # the tone's 80-200 Hz level: knob 0.75 at the default mapping


def band_db(x: np.ndarray) -> float:
    band = sps.sosfilt(intensity_sos(FS), x.astype(np.float64))[int(0.05 * FS) :]
    return 10 * math.log10(float(np.mean(band * band)) + 1e-20)


def capture_band_db(ports: list[str], seconds: float = 1.0) -> float:
    with JackCapture(seconds=seconds, name="vibsynth-monitor-capture") as cap:
        cap.connect(ports[:1])
        cap.arm()
        assert cap.wait(timeout=seconds + 5.0)
        return band_db(cap.data[:, 0])


def wait_status(served: Served, ok, timeout: float = 15.0) -> dict:
    """serve's /status once ``ok(status)`` holds (or as it is after ``timeout``)."""
    deadline = time.monotonic() + timeout
    while True:
        status = served.client.status()
        if ok(status) or time.monotonic() > deadline:
            return status
        time.sleep(0.1)


def test_serve_follow_monitor_follows_what_plays_into_the_system_playback_ports(jack_server, tmp_path):
    served = Served(tmp_path / "serve", device="monitor")
    try:
        assert len(served.in_ports) == 2, served.in_ports
        status = wait_status(served, lambda s: "follow.device" in s)  # ports first, then the follower attaches
        assert status.get("follow.device", "").startswith("monitor (JACK"), status
        quiet_level = status["follow.level_db"]
        quiet_out = capture_band_db(served.out_ports)
        n = int(8 * FS)
        tone = (math.sqrt(2) * 10 ** (TONE_DB / 20) * np.sin(2 * np.pi * 140.0 * np.arange(n) / FS)).astype(np.float32)
        with JackPlayer(n_ports=2, signal=np.stack([tone, tone], axis=1), name="vibsynth-desktop") as player:
            player.connect(["system:playback_1", "system:playback_2"])  # a program playing to the speakers
            player.play()
            # the patch bay reports what it connected after its poll (a child process, a line a poll)
            status = wait_status(
                served, lambda s: abs(s["follow.level_db"] - TONE_DB) < 2.0 and "vibsynth-desktop" in s["follow.device"]
            )
            feeds = status["follow.device"]
            loud_out = capture_band_db(served.out_ports)
        print(
            f"\nmonitor: tracked level {quiet_level:.1f} -> {status['follow.level_db']:.1f} dB; actuator 80-200 Hz "
            f"{quiet_out:.1f} -> {loud_out:.1f} dB; device {feeds!r}"
        )
        assert "vibsynth-desktop" in feeds  # the player feeding the speakers is what serve follows
        assert not any(o in feeds for o in served.out_ports)  # serve's own outputs are not followed
        assert status["follow.level_db"] == pytest.approx(TONE_DB, abs=3.0), status
        assert quiet_level < TONE_DB - 30
        assert loud_out > quiet_out + 30.0
        assert loud_out == pytest.approx(TONE_DB, abs=3.0)  # vibration mode, gain 0: the input's band level
    finally:
        served.close()
