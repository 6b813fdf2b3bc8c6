"""End to end: ``vibsynth serve`` following a JACK input, on a private JACK server killed mid-stream.

The server (:class:`~tests.e2e.test_device_loss_e2e.JackServer`, dummy driver, 48 kHz / 128) is
SIGKILLed while a JACK client plays a 140 Hz tone into serve's input ports. serve reports the
input lost (``follow.device`` says ``lost``/``retrying`` with the reason, ``follow.losses``
counts it, the log says it once), keeps answering OSC, and holds or fades the followed
channel (``follow.on_loss``); when the server is back the input reopens and the tracked level
follows a tone of another level (``follow.recoveries``).

No JACK client of the test process touches the killable server (libjack serves one server per
process: a client left on a dead server crashes later tests): the player runs in a subprocess.
Run: ``.venv/bin/python -m pytest tests/e2e/test_follow_loss_e2e.py -q -s`` (no ``with_jack.sh``).
"""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from tests.e2e.test_device_loss_e2e import OUTAGE_S, Serve
from tests.e2e.test_device_loss_e2e import jack as private_jack  # noqa: F401 - the killable server fixture

pytestmark = pytest.mark.e2e

#: How long each wait for a state may take (serve's retries back off to 2 s; the input's too).
WAIT_S = 15.0

_PLAYER = r"""
import sys, time, threading
import numpy as np
import jack

level_db, seconds, into = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
client = jack.Client("vibsynth-loss-player", no_start_server=True)
fs = client.samplerate
ports = [client.outports.register(f"out_{k}") for k in (1, 2)]
amp = np.sqrt(2) * 10 ** (level_db / 20)
pos = [0]


@client.set_process_callback
def process(frames):
    t = (pos[0] + np.arange(frames)) / fs
    x = (amp * np.sin(2 * np.pi * 140.0 * t)).astype(np.float32)
    for p in ports:
        p.get_array()[:] = x
    pos[0] += frames


client.activate()
if into == "playback":  # the speakers: serve --follow monitor follows what feeds them
    targets = ["system:playback_1", "system:playback_2"]
else:
    targets = sorted(
        (p.name for p in client.get_ports(name_pattern="PortAudio", is_audio=True, is_input=True)),
        key=lambda n: (len(n), n),
    )
for p, t in zip(ports, targets[:2]):
    client.connect(p, t)
print("playing", targets[:2], flush=True)
time.sleep(seconds)
client.deactivate()
client.close()
"""


class Player:
    """A tone into serve's input ports from a subprocess (no JACK client in the test process)."""

    def __init__(self, level_db: float, into: str, seconds: float = 30.0) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _PLAYER, str(level_db), str(seconds), into],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()
        assert "PortAudio" in line or "playback" in line, (
            f"the player found no input port: {line!r} {self.proc.stderr.read()[-2000:]}"
        )

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def wait_for(serve: Serve, ok, what: str, timeout: float = WAIT_S) -> tuple[dict, float]:
    """Poll /status until ``ok(status)``; (status, time.monotonic() seen)."""
    deadline = time.monotonic() + timeout
    while True:
        status = serve.osc.status()
        if ok(status):
            return status, time.monotonic()
        assert time.monotonic() < deadline, f"{what}: {status}\n{serve.log()}"
        time.sleep(0.05)


def level_near(db: float):
    return lambda s: abs(float(s.get("follow.level_db", -200.0)) - db) < 2.0


@pytest.mark.parametrize(("device", "on_loss"), [("system:1,2", "fade"), ("system:1,2", "hold"), ("monitor", "fade")])
def test_a_killed_jack_server_loses_the_follow_input_and_it_recovers(private_jack, tmp_path, device, on_loss):  # noqa: F811
    config = tmp_path / "config.yaml"
    config.write_text(
        "audio: {rate: 48000, block_size: 128}\nknobs: {glide_ms: 0}\nstudio: {enabled: false}\n"
        f"follow: {{enabled: true, device: '{device}', mode: vibration, on_loss: {on_loss}, fade_s: 0.5}}\n"
    )
    private_jack.env.update(VIBSYNTH_CONFIG=str(config), XDG_CONFIG_HOME=str(tmp_path / "xdg"))
    serve = Serve(tmp_path, private_jack)
    into = "playback" if device == "monitor" else "inputs"
    player = None
    try:
        serve.wait_state("streaming", 10.0)
        status, _ = wait_for(serve, lambda s: "(open)" in s.get("follow.device", ""), "the input did not open")
        quiet = status["follow.level_db"]
        player = Player(-50.0, into)
        # the tone's onset is a transient (a short lift of the intensity): wait until the knob settles
        status, _ = wait_for(
            serve,
            lambda s: level_near(-50.0)(s) and abs(float(s["ch1.intensity"]) - 0.75) < 0.03,
            "the tone was not followed",
        )
        playing = status["ch1.intensity"]
        assert quiet < -100  # -50 dB -> knob 0.75

        killed = private_jack.kill()
        player.stop()
        status, seen = wait_for(
            serve,
            lambda s: any(w in s.get("follow.device", "") for w in ("lost", "retrying")) and s["follow.losses"] == 1,
            "the input loss was not reported",
        )
        reported = seen - killed
        device_lost = status["follow.device"]
        # the output is on the same server: its supervisor reports the loss too, on its own clock
        # (a heartbeat or PortAudio's shutdown call), not necessarily before the input's reader did
        wait_for(serve, lambda s: s.get("output") in ("device lost", "recovering"), "the output loss was not reported")
        # serve keeps answering; the followed channel holds or fades (its knobs on the follow layer)
        time.sleep(1.0)
        during = serve.osc.status()
        serve.osc.request("/vibsynth/ping", 3, expect="/vibsynth/pong")
        if on_loss == "hold":  # the followed level of the tone (its tracking wobbles by a few hundredths)
            assert during["ch1.intensity"] == pytest.approx(0.75, abs=0.05)
        else:
            assert during["ch1.intensity"] < 0.01
        while time.monotonic() - killed < OUTAGE_S:
            serve.osc.request("/vibsynth/ping", 4, expect="/vibsynth/pong")
            time.sleep(0.2)

        back = private_jack.start()
        wait_for(serve, lambda s: s.get("output") == "streaming", "the output did not come back")
        status, _ = wait_for(serve, lambda s: "(open)" in s.get("follow.device", ""), "the input did not reopen")
        player = Player(-60.0, into)
        status, seen = wait_for(serve, level_near(-60.0), "the tracked level did not follow the new tone")
        recovered = seen - back
        # the new tone's onset is a transient (a short lift of the intensity): the knob then settles
        status, _ = wait_for(
            serve,
            lambda s: level_near(-60.0)(s) and abs(float(s["ch1.intensity"]) - 0.5) < 0.05,
            "the intensity did not settle at the new tone's knob",
        )
        assert status["follow.losses"] == 1
        assert status["ch1.intensity"] == pytest.approx(0.5, abs=0.05)  # -60 dB -> knob 0.5
        log = serve.log()
        print(
            f"\n[{device}, {on_loss}] JACK killed -> follow.device {device_lost!r} in {1000 * reported:.0f} ms; "
            f"ch1 intensity {playing:.3f} -> {during['ch1.intensity']:.3f} during the loss; server back -> "
            "a -60 dB tone tracked "
            f"({status['follow.level_db']:.1f} dB) in {recovered:.2f} s"
        )
        said = "holding" if on_loss == "hold" else "fading out"
        assert "(lost: JACK server shut down)" in device_lost
        assert log.count("follow: input back; following again") == 1 and status["follow.recoveries"] == 1
        lost_lines = [line for line in log.splitlines() if line.endswith(f"(JACK server shut down); {said}")]
        assert len(lost_lines) == 1 and "follow: input " in lost_lines[0], log  # said once, no flapping
        assert "Traceback" not in log
    finally:
        if player is not None:
            player.stop()
        serve.close()
