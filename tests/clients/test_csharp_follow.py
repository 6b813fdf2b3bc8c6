"""The C# client's live Follow methods (SetFollow, SetFollowGain/Gate/Range/Focus, GetFollow...) against a
real ``vibsynth serve`` following a WAV file (tests/clients/csharp/FollowCheck.cs, compiled with mcs and
run with mono). What the C# side reports is checked, and the server's state is read independently with
the Python client. Skips without mono (tests/clients/mono.py).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

import vibsynth
from tests.clients.mono import CHECK_MAIN, CLIENT, HERE, compile_cs, require_mono, run_mono
from tests.e2e.test_osc_e2e import start_serve, stop_serve
from vibsynth.settings.models import bounds_of
from vibsynth.settings.models_follow import Follow

FS = 48000


@pytest.fixture(scope="module")
def follow_check(tmp_path_factory) -> Path:
    require_mono()
    folder = tmp_path_factory.mktemp("csharp-follow")
    return compile_cs(folder / "FollowCheck.exe", CLIENT, HERE / "FollowCheck.cs", CHECK_MAIN)


@pytest.fixture(scope="module")
def served(tmp_path_factory, follow_check):
    """``vibsynth serve`` with 2 channels on the null output, following a mono WAV (a noisy 140 Hz tone)."""
    tmp = tmp_path_factory.mktemp("csharp-follow-serve")
    rng = np.random.default_rng(24)
    t = np.arange(30 * FS) / FS
    x = 0.2 * np.sin(2 * np.pi * 140.0 * t) + 0.02 * rng.standard_normal(t.size)
    wav = tmp / "tone.wav"
    wavfile.write(wav, FS, (x * 32767).astype(np.int16))
    config = f"audio:\n  channels: 2\nfollow:\n  enabled: true\n  device: {wav}\n  mode: audio\n"
    proc, port = start_serve(tmp, extra_config=config)
    try:
        with vibsynth.Client(port=port, timeout=5.0) as client:
            # serve answers OSC before its follower runs (it opens the input after): until then every
            # follow message is answered "follow is not running"
            deadline = time.monotonic() + 30.0
            while "follow.device" not in client.status():
                assert time.monotonic() < deadline, "serve's follower did not start"
                time.sleep(0.05)
            yield port, client
    finally:
        stop_serve(proc)


def test_follow_settings_set_read_back_refused_and_checked(served, follow_check):
    port, python = served
    seen = run_mono(follow_check, "follow", port)
    assert float(seen["default.range"]) == Follow().range_db
    assert seen["default.focus"] == "all"
    # set by the C# client, read back by it
    assert (float(seen["gain"]), float(seen["gate"]), float(seen["range"])) == (4.5, -45.0, 30.0)
    assert seen["focus"] == "effects" and float(seen["async.range"]) == 30.0
    # per channel: off hands channel 2 to its knobs; all off, all on
    assert (seen["ch1.follow"], seen["ch2.follow"]) == ("true", "false")
    assert (seen["ch1.driver"], seen["ch2.driver"]) == ("follow", "knobs")
    assert seen["all_off.ch1"] == "false" and seen["all_on.ch2"] == "true"
    # the server's refusals, in order, with its ranges; nothing changed
    low, high = bounds_of("follow.range_db")
    assert seen["refused.count"] == "4"
    assert seen["refused.error0"] == (
        f"/vibsynth/follow/range: follow range (dB) 200 is outside the allowed range [{low:g}, {high:g}]"
    )
    assert seen["refused.error1"].startswith("/vibsynth/follow/gain: ") and "[-60, 60]" in seen["refused.error1"]
    assert (
        seen["refused.error2"].startswith("/vibsynth/follow/focus: ")
        and "all, effects, bass, beat" in seen["refused.error2"]
    )
    assert seen["refused.error3"].startswith("/vibsynth/ch/9/follow: channel 9 out of range")
    assert (float(seen["refused.gain"]), float(seen["refused.range"]), seen["refused.focus"]) == (
        4.5,
        30.0,
        "effects",
    )
    # refused by the client itself, before anything is sent (the first line of each message)
    bad = {
        key[4:-5]: (kind, seen[key[:-5] + ".message"].split("\\n")[0])
        for key, kind in seen.items()
        if key.startswith("bad.") and key.endswith(".type")
    }
    assert bad == {
        "gain_nan": ("ArgumentException", "follow gain (dB) must be a finite number, got NaN"),
        "range_inf": ("ArgumentException", "follow range (dB) must be a finite number, got Infinity"),
        "focus_null": ("ArgumentNullException", "follow focus must not be null"),
        "focus_empty": ("ArgumentException", "follow focus must be a non-empty text without NUL characters"),
        "channel_zero": ("ArgumentOutOfRangeException", "channel 0 is outside 1..64 (channels count from 1)"),
    }
    assert seen["bad.sent"] == "0"
    # a bundle of follow setters applies
    assert (float(seen["bundle.gain"]), float(seen["bundle.range"])) == (-3.0, 48.0)
    # the server's state, read by another client
    assert python.follow_setting("gain") == -3.0 and python.follow_setting("focus") == "effects"
    assert python.follow_setting("gate") == -45.0
    reply = python.request("/vibsynth/follow/get", "range", types="s", match=lambda r: r.address.endswith("/range"))
    assert tuple(reply.args) == (48.0,)
    assert python.get("follow", 1) is True and python.get("follow", 2) is True
