"""End to end (issue 15): a touch source moved across a 4-actuator layout over OSC, heard in JACK.

``vibsynth serve`` runs on the JACK dummy server with 4 channels placed on a line 10 cm apart.
A source is moved across the line over OSC (a stream of positions, as a VR app sends them);
at each stop every channel is captured for one whole loop of the noise bank (4 s: the band
levels of a periodic signal are exact over one period) and its 80-200 Hz band level is measured
with the DSP core. The loudest channel must be the one the law puts first, and every other
channel the source reaches must lie ``10 log10(w / w_max)`` dB below it, within 1 dB; channels
it does not reach are silent.

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_spatial_e2e.py -q -s``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from tests.e2e.jackutil import REALTIME, JackCapture, portaudio_output_ports
from tests.e2e.oscclient import OscClient
from tests.e2e.test_osc_e2e import jack_available, start_serve, stop_serve, unavailable
from vibsynth.dsp.intensity import intensity_level_db
from vibsynth.dsp.spatial import SpatialLayout

pytestmark = pytest.mark.e2e

#: The layout: channels 1..4 at x = 0, 0.1, 0.2, 0.3 m.
XS = (0.0, 0.1, 0.2, 0.3)
LAYOUT = "audio:\n  channels: 4\nlayout:\n" + "".join(f"  {c + 1}: {{x: {x}, y: 0.0}}\n" for c, x in enumerate(XS))
LOOP_S = 4.0  # bank.loop_seconds (default)


@pytest.fixture
def served(tmp_path):
    if not jack_available():
        unavailable("no JACK server reachable (run under scripts/with_jack.sh) or JACK-Client missing")
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    proc, port = start_serve(tmp_path, output="sounddevice", extra_config=LAYOUT, env=env)
    client = OscClient(port)
    yield client
    client.close()
    stop_serve(proc)


def move(client: OscClient, start: float, stop: float, seconds: float = 0.4) -> None:
    """Send positions from ``start`` to ``stop`` every 10 ms (a hand moving at 90 Hz frame rate or so)."""
    steps = max(1, int(seconds / 0.01))
    for k in range(1, steps + 1):
        client.send("/vibsynth/source/1/pos", start + (stop - start) * k / steps, 0.0)
        time.sleep(0.01)


def band_levels(client: OscClient) -> list[float]:
    """80-200 Hz band level (dB) of each channel over one captured loop."""
    with JackCapture(LOOP_S, n_ports=4) as cap:
        ports = portaudio_output_ports(cap.client)
        assert len(ports) >= 4, f"serve registered {len(ports)} PortAudio output ports"
        cap.connect(ports[:4])
        cap.arm()
        assert cap.wait(), "capture did not complete"
        data, rate = cap.data.astype(np.float64), cap.rate
    return [intensity_level_db(data[:, c], fs=rate) for c in range(4)]


def check_stop(client: OscClient, x: float, law: str, radius: float) -> str:
    weights = SpatialLayout([(xc, 0.0, 0.0) for xc in XS]).weights(law, (x, 0.0, 0.0), radius)
    # a dropped block on this shared machine can spoil one capture: judge the first clean one of three
    for _attempt in range(3):
        levels = band_levels(client)
        loudest = int(np.argmax(levels))
        errors = [
            levels[c] - levels[loudest] - 10 * math.log10(weights[c] / weights[loudest])
            for c in range(4)
            if weights[c] > 0
        ]
        silent_ok = all(levels[c] == -math.inf for c in range(4) if weights[c] == 0)
        if loudest == int(np.argmax(weights)) and max(abs(e) for e in errors) <= 1.0 and silent_ok:
            break
    line = f"{law:>8} x={x:.3f}: levels " + " ".join(f"{v:7.2f}" for v in levels)
    line += "  law " + " ".join(f"{10 * math.log10(w) if w > 0 else -math.inf:7.2f}" for w in weights)
    assert loudest == int(np.argmax(weights)), line
    assert max(abs(e) for e in errors) <= 1.0, line
    assert silent_ok, line
    return line


@REALTIME
def test_a_source_moved_across_the_layout_is_heard_where_the_law_puts_it(served):
    client = served
    client.send("/vibsynth/source/1/texture", 0.8, 0.0)
    client.send("/vibsynth/source/1/radius", 0.15)
    client.send("/vibsynth/source/1/rolloff", "linear")
    client.send("/vibsynth/source/1/pos", -0.05, 0.0)
    client.send("/vibsynth/source/1/on", 1)
    lines, x = [], -0.05
    for stop in (0.02, 0.13, 0.27):  # near channel 1, between 2 and 3, near channel 4
        move(client, x, stop)
        x = stop
        time.sleep(0.2)  # the last glide and mix are over
        lines.append(check_stop(client, x, "linear", 0.15))
        # what the channels play, as the server reports it, is what the law gives
        texture = client.request("/vibsynth/ch/2/get", "texture", expect="/vibsynth/ch/2/texture").args
        w = max(0.0, 1 - abs(x - XS[1]) / 0.15)
        assert texture[0] == pytest.approx(0.8 + 10 * math.log10(w) / 40 if w > 0 else 0.0, abs=1e-5)
    client.send("/vibsynth/source/1/rolloff", "phantom")
    move(client, x, 0.13)
    time.sleep(0.2)
    lines.append(check_stop(client, 0.13, "phantom", 0.15))
    print("\n" + "\n".join(lines))
