"""End to end: a stereo input pans a touch source between two actuators (``pan:`` of a source route).

serve on JACK with two actuators 30 cm apart (a layout; sources with a 30 cm linear roll-off) and
one route, ``{source: 1, inputs: [1, 2], pan: {left: actuator 1, right: actuator 2}}``. A JACK
client plays a 140 Hz tone into input 1 only, then into both, then into input 2 only; another
captures both actuators. The 80-200 Hz levels show the move by the layout's roll-off law: all on
actuator 1, then both 3 dB below the source (half the power each), then all on actuator 2.

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_follow_pan_e2e.py -q -s``.
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

SEGMENT_S = 2.0
TONE_DB = -50.0
TOP = "layout:\n  1: {x: 0.0, y: 0.0}\n  2: {x: 0.3, y: 0.0}\nsources:\n  radius: 0.3\n  rolloff: linear\n"
ROUTE = "  routes:\n    - {source: 1, inputs: [1, 2], pan: {left: [0.0, 0.0], right: [0.3, 0.0]}}\n"


def band_db(x: np.ndarray) -> float:
    band = sps.sosfilt(intensity_sos(FS), x.astype(np.float64))[int(0.05 * FS) :]
    return 10 * math.log10(float(np.mean(band * band)) + 1e-20)


def test_the_stereo_balance_moves_the_source_across_the_actuators(jack_server, tmp_path):
    served = Served(tmp_path / "serve", extra=ROUTE, channels=2, top=TOP)
    try:
        assert len(served.in_ports) == 2 and len(served.out_ports) == 2, (served.in_ports, served.out_ports)
        n = int(SEGMENT_S * FS)
        tone = math.sqrt(2) * 10 ** (TONE_DB / 20) * np.sin(2 * np.pi * 140.0 * np.arange(3 * n) / FS)
        gains = np.repeat(np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), n, axis=0)
        stereo = (tone[:, None] * gains).astype(np.float32)
        with JackPlayer(n_ports=2, signal=stereo) as player, JackCapture(3 * SEGMENT_S + 1.0, n_ports=2) as cap:
            player.connect(served.in_ports)
            cap.connect(served.out_ports)
            cap.arm()
            time.sleep(0.1)
            player.play()
            assert cap.wait(3 * SEGMENT_S + 10)
            offset = int(player.start_frame - cap.start_frame)
            gaps = cap.gaps + player.gaps
        levels = []
        for k in range(3):  # the last second of each segment: the source has arrived
            a = offset + k * n + int(0.9 * FS)
            levels.append((band_db(cap.data[a : a + int(FS), 0]), band_db(cap.data[a : a + int(FS), 1])))
        print(
            "\npan: actuator 1 / 2, 80-200 Hz dB: "
            + "; ".join(f"{name} {a:.1f} / {b:.1f}" for name, (a, b) in zip(("left", "both", "right"), levels))
            + f" (missed cycles {gaps})"
        )
        (l1, l2), (c1, c2), (r1, r2) = levels
        # left only: the mix (mean) is the tone -6 dB, all of it on actuator 1
        assert l1 == pytest.approx(TONE_DB - 6.0, abs=1.5) and l2 < l1 - 30
        # both: the mix is the tone, half its power on each actuator (-3 dB)
        assert c1 == pytest.approx(TONE_DB - 3.0, abs=1.5) and c2 == pytest.approx(TONE_DB - 3.0, abs=1.5)
        assert r2 == pytest.approx(TONE_DB - 6.0, abs=1.5) and r1 < r2 - 30
        status = served.client.status()
        assert "follow.device" in status
    finally:
        served.close()
