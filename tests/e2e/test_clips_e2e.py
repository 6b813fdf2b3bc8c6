"""End to end: haptic clips played by the real ``vibsynth serve`` on JACK, and from JACK MIDI notes (issue 16).

* A clip with known keyframes, started by a timetagged OSC bundle, is captured from JACK: the
  80-200 Hz band level follows the keyframes (within 1 dB at each), the balance measured by the
  analysis follows the balance curve, and the onset is within one block of the requested frame
  (the frame a knob jump in the same bundle lands on).
* A JACK MIDI note plays a looping clip through the note map; its note-off stops it.

Skips with a clear message when JACK, oscsend or python-rtmidi with JACK are missing, unless
``VIBSYNTH_E2E_REQUIRED=1`` (CI), where it fails.
Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_clips_e2e.py -q -s``.
"""

from __future__ import annotations

import os
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.jackutil import REALTIME
from tests.e2e.oscclient import OscClient
from tests.e2e.test_midi_e2e import jack_env, play_to_receiver  # noqa: F401  (a fixture)
from tests.e2e.test_osc_e2e import jack_available, start_serve, stop_serve, unavailable
from vibsynth.control.osc.codec import encode_bundle, encode_message, unix_to_ntp
from vibsynth.dsp.basis import to_db
from vibsynth.dsp.filterbank import band_power_frames
from vibsynth.dsp.intensity import intensity_level_db, knob_to_level_db
from vibsynth.formats.basis_file import default_basis

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[2]
CEILING_DB, RANGE_DB = -40.0, 40.0  # the defaults of knobs.ceiling_db / range_db
BLOCK = 128  # audio.block_size (and scripts/with_jack.sh's period)
LEAD_S = 0.5  # the bundle's timetag, ahead of the send

#: plateaus (ms): intensity and balance held between two equal keyframes, short ramps between
STAIRS = """\
duration_ms: 5200
keyframes:
  - {t_ms: 0, intensity: 0.5, balance: -1.0}
  - {t_ms: 1100, intensity: 0.5, balance: -1.0}
  - {t_ms: 1200, intensity: 0.85, balance: 1.0}
  - {t_ms: 2300, intensity: 0.85, balance: 1.0, interp: hold}
  - {t_ms: 2400, intensity: 0.25, balance: 0.0}
  - {t_ms: 3500, intensity: 0.25, balance: 0.0}
  - {t_ms: 4100, intensity: 0.65, balance: -2.0, interp: smooth}
  - {t_ms: 5200, intensity: 0.65, balance: -2.0}
"""
DURATION_S = 5.2
#: (first ms, last ms, intensity, balance) of each plateau: the keyframes that start and end it
PLATEAUS = [(0, 1100, 0.5, -1.0), (1200, 2300, 0.85, 1.0), (2400, 3500, 0.25, 0.0), (4100, 5200, 0.65, -2.0)]
#: the bank's loop (bank.loop_seconds): the level is measured over exactly one loop inside each
#: plateau, from 50 ms after its first keyframe to 50 ms before its last. The FFT of one period of
#: a periodic signal has no leakage, so the measure is the level played, not an estimate of it
#: (a 0.45 s window of the loop scatters by +-0.6 dB around it, depending on where it falls).
LOOP_S = 1.0


def _balance(basis, x: np.ndarray, fs: float) -> float:
    t1 = basis.scores(to_db(band_power_frames(x, fs=fs, window_s=0.2, hop_s=0.1)))[:, 0].mean()
    return float(basis.balance_from_t1(t1))


@pytest.fixture
def clip_serve(tmp_path):
    if not jack_available():
        unavailable("no JACK server reachable (run under scripts/with_jack.sh) or JACK-Client missing")
    clips = tmp_path / "clips"
    clips.mkdir()
    (clips / "stairs.yaml").write_text(STAIRS, encoding="utf-8")
    env = dict(os.environ, VIBSYNTH_HOST_API="JACK", JACK_NO_AUDIO_RESERVATION="1")
    extra = (
        f"clips:\n  user_dir: {clips}\n  watch: false\naudio:\n  block_size: {BLOCK}\n  channels: 2\n"
        f"bank:\n  loop_seconds: {LOOP_S}\n"
    )
    proc, port = start_serve(tmp_path, output="sounddevice", env=env, extra_config=extra)
    yield port
    stop_serve(proc)


def _onset(x: np.ndarray, near: int, rate: int) -> int:
    """The first non-zero sample within 100 ms of ``near`` (an AssertionError when there is none)."""
    a = max(0, near - int(0.1 * rate))
    nonzero = np.flatnonzero(np.abs(x[a : near + int(0.1 * rate)]) > 1e-7)
    first = np.flatnonzero(np.abs(x) > 1e-7)
    where = f"first sample at {first[0] - near:+d} frames" if first.size else "all silent"
    assert nonzero.size, f"no onset within 100 ms of frame {near} ({where})"
    return a + int(nonzero[0])


@REALTIME
def test_a_timetagged_clip_follows_its_keyframes_in_the_captured_output(clip_serve):
    """One bundle starts the clip on channel 1 and jumps channel 2's intensity (glide 0): both are
    the frame the server gave the timetag, so the clip's onset is compared with the knob's, sample
    for sample (the wall-clock error of the timetag itself is printed, as test_osc_e2e checks it)."""
    from tests.e2e.jackutil import JackCapture, portaudio_output_ports

    client = OscClient(clip_serve)
    try:
        client.send("/vibsynth/ch/2/glide", 0.0)
        client.request("/vibsynth/sync", 1, expect="/vibsynth/synced")
        with JackCapture(LEAD_S + DURATION_S + 1.5, n_ports=2) as cap:
            cap.connect(portaudio_output_ports(cap.client)[:2])
            cap.arm()
            time.sleep(0.3)
            frame_sent = cap.frame_time_now()
            wall = time.time()
            bundle = encode_bundle(
                unix_to_ntp(wall + LEAD_S),
                [
                    encode_message("/vibsynth/ch/1/play", ("stairs",), "s"),
                    encode_message("/vibsynth/ch/2/intensity", (0.5,), "f"),
                ],
            )
            client.sock.sendto(bundle, client.target)
            time.sleep(1.0)
            status = client.status()
            assert status["ch1.clip"] == "stairs" and status["clips_playing"] == 1, status
            assert cap.wait()
            x, knob, start, rate = cap.data[:, 0].astype(np.float64), cap.data[:, 1], cap.start_frame, cap.rate
        timetag = frame_sent - start + int(round(LEAD_S * rate))
        requested = _onset(knob, timetag, rate)  # the frame the server gave the timetag
        onset = _onset(x, requested, rate)
        assert np.all(np.abs(x[:onset]) <= 1e-7)  # silent before
        basis = default_basis()
        lines = [
            f"clip onset - requested frame: {onset - requested:+d} frames (block {BLOCK}); "
            f"requested - timetag on the JACK clock: {1e3 * (requested - timetag) / rate:+.2f} ms"
        ]
        levels, balances = [], []
        n = int(round(LOOP_S * rate))
        for first, last, k, bal in PLATEAUS:
            want = knob_to_level_db(k, ceiling_db=CEILING_DB, range_db=RANGE_DB)
            assert last - first - 100 >= 1000 * LOOP_S  # one loop fits 50 ms inside both keyframes
            a = onset + int((first + 50) * rate / 1000)
            level = intensity_level_db(x[a : a + n], fs=rate)
            levels.append(level - want)
            lines.append(f"keyframes {first:4d}-{last:4d} ms: level {level:6.2f} dB (want {want:6.2f})")
            a = onset + int((first + 100) * rate / 1000)
            measured = _balance(basis, x[a : a + int((last - first - 200) * rate / 1000)], rate)
            balances.append(measured - bal)
            lines.append(f"plateau {first}-{last} ms: balance {measured:+.2f} (curve {bal:+.1f})")
        print("\n" + "\n".join(lines))
        assert abs(onset - requested) <= BLOCK, lines[0]
        assert max(abs(d) for d in levels) <= 0.5  # the issue asks 1 dB; one loop measures it exactly
        assert max(abs(d) for d in balances) <= 0.35
        end = onset + int(DURATION_S * rate)
        assert np.max(np.abs(x[end + int(0.2 * rate) :])) <= 1e-7  # back to the knob state: silent
    finally:
        client.close()


# ---------------------------------------------------------------------- JACK MIDI: a note plays a clip
RECEIVER = textwrap.dedent("""
    import argparse, sys, time
    import numpy as np
    from vibsynth.settings.config import default_config_data
    from vibsynth.settings.typed import settings_of
    from vibsynth.control.midi import adapter as midi
    from vibsynth.control.clips.adapter import ClipService
    from vibsynth.control.controller import Controller
    from vibsynth.engine.bank import BankSpec, build_bank
    from vibsynth.engine.engine import Engine
    from vibsynth.formats.basis_file import default_basis
    from vibsynth.settings.clips import ClipLibrary, shipped_clips_dir

    fs, seconds, out_path = 8000.0, float(sys.argv[1]), sys.argv[2]
    engine = Engine(build_bank(default_basis(), BankSpec(fs=fs, loop_seconds=1.0, levels=15)), channels=1,
                    ceiling_db=-24.0, max_block=80)
    controller = Controller(engine)
    clips = ClipService(controller, ClipLibrary(shipped_clips_dir(), None), watch=False)
    clips.start()
    data = default_config_data()
    data["midi_clips"]["notes"] = [{"note": 38, "clip": "rain", "loops": 0}]
    data["midi_clips"]["release_ms"] = 20.0
    parser = argparse.ArgumentParser()
    midi.add_arguments(parser)
    args = parser.parse_args(["--midi-virtual"])
    server = midi.create(settings_of(data), args, controller, None)
    assert server is not None, "create() returned None"
    server.start()
    print("READY", server.describe(), flush=True)
    block, frames = 80, int(seconds * fs)
    out = np.zeros(frames, dtype=np.float32)
    t0 = time.monotonic()
    playing = []
    for pos in range(0, frames, block):
        delay = t0 + pos / fs - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        out[pos:pos + block] = engine.render(block)[:, 0]
        now = clips.player.playing(0)
        playing.append(now.name if now is not None else "")
    server.stop()
    clips.stop()
    np.save(out_path, out)
    print("DONE", server.received, "late", engine.stats.late_commands, "played", sorted(set(playing)), flush=True)
""")


@REALTIME
def test_a_jack_midi_note_plays_a_clip_and_its_note_off_stops_it(jack_env, tmp_path):  # noqa: F811
    out_path = tmp_path / "out.npy"
    # silent 1 s; note 38 (the rain clip, looped) for 2 s; released: the clip stops
    script = "sleep 1.0\non 38 127\nsleep 2.0\noff 38\n"
    rest = play_to_receiver(RECEIVER, 5.0, script, jack_env, out_path)
    assert "DONE" in rest and "'rain'" in rest, rest
    x = np.load(out_path).astype(np.float64)
    fs = 8000

    def rms(a: float, b: float) -> float:
        return float(np.sqrt(np.mean(x[int(a * fs) : int(b * fs)] ** 2)))

    # the sender connects within a moment; allow 0.5 s of scheduling slack on a busy machine
    assert rms(0.0, 0.8) == 0.0
    assert rms(1.7, 2.7) > 0.0 and intensity_level_db(x[int(1.7 * fs) : int(2.7 * fs)], fs=fs) > -70.0
    assert rms(4.0, 5.0) == 0.0  # stopped by the note-off: no stuck clip
    print(f"\nMIDI clip: rms {rms(1.7, 2.7):.2e} while held, {rms(4.0, 5.0):.1e} after the note-off; {rest.strip()}")
