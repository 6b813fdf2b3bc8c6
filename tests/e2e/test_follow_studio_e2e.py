"""The studio's Follow panel in a real browser, on a real ``vibsynth serve --follow`` on the JACK dummy server.

``vibsynth serve`` (PortAudio on JACK, two channels, following ``system:1,2`` in vibration mode)
opens input ports beside its output ports; a JACK client in the test plays a 140 Hz tone into
them: first quiet (band level -70 dB: intensity knob 0.25 at the default mapping), then a 20 dB
step up (-50 dB: knob 0.75). Headless Chromium shows the studio:

* the meter (``follow-meter``) moves with the played level (its peak, dBFS);
* the trace (``follow-trace``) shows the tracked intensity rising with the step: the newest point
  and the blue line drawn on the canvas (read back from its pixels);
* gain, gate (keyboard steps) and focus (the select) reach the server: read back with
  ``/vibsynth/follow/get`` over OSC;
* ``follow-toggle`` off on channel 1 hands it back to its knobs (the intensity OSC set while it
  followed plays; channel 2 still follows); on again, follow takes it back;
* the input picker lists the JACK input device and switching to it follows the new ports.

Every wait is an explicit wait on a condition with a deadline. The run writes a screenshot of
the panel (``follow-studio.png`` in the test's folder, and to ``$VIBSYNTH_FOLLOW_SCREENSHOT``
when set: docs/images/follow-studio.png comes from there).

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_follow_studio_e2e.py -q``.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.jackutil import JackPlayer, jack_ports, new_ports, require_jack
from tests.e2e.studioutil import (
    by_testid,
    chromium,
    console_errors,
    open_studio,
    require_browser,
    start_serve,
    wait_for,
)

pytestmark = pytest.mark.e2e

FS = 48000
QUIET_DB, LOUD_DB = -70.0, -50.0  # band levels: knob 0.25 and 0.75 (knobs.ceiling_db -40, range_db 40)
QUIET_S, LOUD_S = 6.0, 60.0
CONFIG = "follow:\n  enabled: true\n  device: 'system:1,2'\n  mode: vibration\nknobs:\n  glide_ms: 0\n"


def knob_of(level_db: float) -> float:
    return 1.0 + (level_db + 40.0) / 40.0


def tone(seconds: float, level_db: float, start: int = 0) -> np.ndarray:
    n = int(seconds * FS)
    t = (start + np.arange(n)) / FS
    return (np.sqrt(2.0) * 10 ** (level_db / 20) * np.sin(2 * np.pi * 140.0 * t)).astype(np.float32)


def step_signal() -> np.ndarray:
    """The quiet tone, then the loud one (phase continuous), on two ports."""
    quiet = tone(QUIET_S, QUIET_DB)
    loud = tone(LOUD_S, LOUD_DB, start=quiet.size)
    x = np.concatenate([quiet, loud])
    return np.stack([x, x], axis=1)


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    require_jack()
    require_browser()
    before = jack_ports()
    service = start_serve(tmp_path_factory.mktemp("follow-studio"), output="sounddevice", rate=FS, extra_config=CONFIG)
    service.in_ports = new_ports(before)
    yield service
    service.stop()


@pytest.fixture(scope="module")
def driver(served):
    browser = chromium(1400, 1600)
    yield browser
    browser.quit()


@pytest.fixture
def page(driver, served):
    console_errors(driver)
    open_studio(driver, served)
    wait_for(lambda: by_testid(driver, "follow-toggle"), what="the follow panel's routes")
    yield driver
    assert console_errors(driver) == []


def follow_get(served, name: str):
    return served.osc.request("/vibsynth/follow/get", name, expect=f"/vibsynth/follow/{name}").args[0]


def data(driver, testid: str, name: str) -> float:
    return float(by_testid(driver, testid).get_attribute(f"data-{name}"))


#: Mean height (canvas rows from the top) of the intensity line's pixels per column (NaN where none).
INTENSITY_ROWS = """
const canvas = document.querySelector('[data-testid="follow-trace"]');
const {width, height} = canvas;
const pixels = canvas.getContext('2d').getImageData(0, 0, width, height).data;
const rows = [];
for (let x = 0; x < width; x++) {
  let sum = 0, count = 0;
  for (let y = 0; y < height; y++) {
    const i = 4 * (y * width + x);
    if (Math.abs(pixels[i] - 31) < 40 && Math.abs(pixels[i + 1] - 111) < 40 && Math.abs(pixels[i + 2] - 235) < 40) {
      sum += y; count++;
    }
  }
  rows.push(count ? sum / count : null);
}
return rows;
"""


def test_the_meter_and_the_trace_follow_a_level_step(page, served, tmp_path):
    assert len(served.in_ports) == 2, served.in_ports
    silent_peak = data(page, "follow-meter", "level-db")
    with JackPlayer(n_ports=2, signal=step_signal(), name="follow-studio") as player:
        player.connect(served.in_ports)
        player.play()
        # quiet: the meter shows the tone's peak (rms + 3 dB), the trace the knob of its band level
        quiet_peak = QUIET_DB + 3.0
        wait_for(lambda: abs(data(page, "follow-meter", "level-db") - quiet_peak) < 2.0, what="the quiet level")
        wait_for(
            lambda: abs(data(page, "follow-trace", "intensity") - knob_of(QUIET_DB)) < 0.04,
            what="the quiet intensity in the trace",
        )
        settled = data(page, "follow-trace", "t") + 0.5  # the newest 0.4 s of the line drawn are all quiet
        wait_for(lambda: data(page, "follow-trace", "t") > settled, what="the quiet trace")
        quiet_rows = page.execute_script(INTENSITY_ROWS)
        loud_peak = LOUD_DB + 3.0
        wait_for(
            lambda: abs(data(page, "follow-meter", "level-db") - loud_peak) < 2.0, timeout=QUIET_S + 10, what="the step"
        )
        wait_for(
            lambda: abs(data(page, "follow-trace", "intensity") - knob_of(LOUD_DB)) < 0.04,
            what="the loud intensity in the trace",
        )
        wait_for(lambda: data(page, "follow-trace", "level-db") > LOUD_DB - 1.0, what="the tracked level")
        settled = data(page, "follow-trace", "t") + 0.5
        wait_for(lambda: data(page, "follow-trace", "t") > settled, what="the loud trace")
        # the line drawn: 20 dB louder = half the intensity axis higher, at the newest end of the trace
        loud_rows = page.execute_script(INTENSITY_ROWS)
        width = len(loud_rows)
        newest = [r for r in loud_rows[width - 60 : width - 42] if r is not None]
        before = [r for r in quiet_rows[width - 60 : width - 42] if r is not None]
        assert newest and before, "no intensity line drawn"
        plot_height = 200 - 10 - 22
        assert np.median(before) - np.median(newest) == pytest.approx(0.5 * plot_height, abs=8)
        assert page.find_element("id", "follow-gate-state").text == "open"
        panel = page.find_element("id", "follow-panel")
        page.execute_script("arguments[0].scrollIntoView()", panel)
        shot = tmp_path / "follow-studio.png"
        panel.screenshot(str(shot))
        if os.environ.get("VIBSYNTH_FOLLOW_SCREENSHOT"):
            shutil.copyfile(shot, Path(os.environ["VIBSYNTH_FOLLOW_SCREENSHOT"]))
    assert silent_peak < QUIET_DB


def test_gain_gate_and_focus_reach_the_server(page, served):
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select

    gain = by_testid(page, "follow-gain")
    low, high = float(gain.get_attribute("min")), float(gain.get_attribute("max"))
    assert (low, high) == (-60.0, 60.0)  # follow.gain_db's range, delivered by the server
    start = follow_get(served, "gain")
    gain.send_keys(Keys.ARROW_RIGHT, Keys.ARROW_RIGHT)  # 1 % of the range each
    wait_for(lambda: abs(follow_get(served, "gain") - (start + 0.02 * (high - low))) < 1e-3, what="the gain")
    gate = by_testid(page, "follow-gate")
    gate_start = follow_get(served, "gate")
    g_low, g_high = float(gate.get_attribute("min")), float(gate.get_attribute("max"))
    gate.send_keys(Keys.PAGE_UP)  # 10 % of the range
    want = min(g_high, gate_start + 0.1 * (g_high - g_low))
    wait_for(lambda: abs(follow_get(served, "gate") - want) < 1e-3, what="the gate")
    Select(by_testid(page, "follow-focus")).select_by_value("effects")
    wait_for(lambda: follow_get(served, "focus") == "effects", what="the focus")
    # and a change made over OSC shows on the page
    served.osc.send("/vibsynth/follow/gain", -6.0)
    wait_for(lambda: float(by_testid(page, "follow-gain").get_attribute("value")) == -6.0, what="OSC's gain shown")
    served.osc.send("/vibsynth/follow/gain", 0.0)
    served.osc.send("/vibsynth/follow/gate", gate_start)
    served.osc.send("/vibsynth/follow/focus", "all")
    wait_for(lambda: follow_get(served, "gain") == 0.0 and follow_get(served, "focus") == "all", what="reset")


def test_follow_toggle_off_hands_the_channel_back_to_the_knobs(page, served):
    with JackPlayer(n_ports=2, signal=step_signal()[int(QUIET_S * FS) :], name="follow-toggle") as player:
        player.connect(served.in_ports)
        player.play()
        wait_for(lambda: abs(served.get("intensity", 1) - knob_of(LOUD_DB)) < 0.05, what="channel 1 following")
        served.osc.send("/vibsynth/ch/1/intensity", 0.1)  # remembered: the knobs play it when follow is off
        toggle = next(
            t
            for t in page.find_elements("css selector", '[data-testid="follow-toggle"]')
            if t.get_attribute("data-channel") == "1"
        )
        assert toggle.get_attribute("aria-pressed") == "true"
        toggle.click()
        wait_for(
            lambda: served.osc.request("/vibsynth/ch/1/get", "follow", expect="/vibsynth/ch/1/follow").args[0] == 0,
            what="follow off on channel 1",
        )
        wait_for(lambda: abs(served.get("intensity", 1) - 0.1) < 1e-4, what="channel 1's knobs")
        assert abs(served.get("intensity", 2) - knob_of(LOUD_DB)) < 0.05  # channel 2 still follows
        wait_for(lambda: toggle.get_attribute("aria-pressed") == "false", what="the toggle shown off")
        toggle.click()
        wait_for(lambda: abs(served.get("intensity", 1) - knob_of(LOUD_DB)) < 0.05, what="channel 1 following again")


def test_the_input_picker_lists_the_jack_input_and_switches_to_it(page, served):
    from selenium.webdriver.support.ui import Select

    picker = by_testid(page, "follow-input")
    wait_for(lambda: len(picker.find_elements("css selector", "option")) > 1, what="the input devices")
    names = [o.get_attribute("value") for o in picker.find_elements("css selector", "option")]
    assert "system" in names, names
    before = jack_ports()
    Select(picker).select_by_value("system")
    wait_for(lambda: new_ports(before), what="the new input's JACK ports")
    ports = new_ports(before)
    assert len(ports) == 2 and page.find_element("id", "follow-error").text == ""
    wait_for(lambda: "system" in picker.find_elements("css selector", "option")[0].text, what="the switch shown")
    with JackPlayer(n_ports=2, signal=step_signal()[int(QUIET_S * FS) :], name="follow-switch") as player:
        player.connect(ports)
        player.play()
        wait_for(
            lambda: abs(data(page, "follow-meter", "level-db") - (LOUD_DB + 3)) < 2.0, what="the new input's level"
        )
    assert served.osc.status()["follow.device"].startswith("system")


def test_without_follow_the_panel_says_how_to_start_and_starts_the_picked_input(tmp_path):
    from selenium.webdriver.support.ui import Select

    require_jack()
    require_browser()
    served = start_serve(tmp_path / "serve", output="sounddevice", rate=FS, extra_config="knobs:\n  glide_ms: 0\n")
    browser = chromium(1400, 1600)
    try:
        open_studio(browser, served)
        hint = by_testid(browser, "follow-hint")
        wait_for(lambda: "--follow" in hint.text, what="the hint")
        assert by_testid(browser, "follow-gain").get_attribute("disabled") is not None
        assert not browser.find_elements("css selector", '[data-testid="follow-toggle"]')
        picker = by_testid(browser, "follow-input")
        wait_for(lambda: len(picker.find_elements("css selector", "option")) > 1, what="the input devices")
        before = jack_ports()
        Select(picker).select_by_value("system")

        def ports_up() -> bool:
            shown = by_testid(browser, "follow-error").text
            assert not shown, shown  # wait_for shows the panel's error at its deadline
            return len(new_ports(before)) == 2

        wait_for(ports_up, what="the input's JACK ports")
        wait_for(
            lambda: len(browser.find_elements("css selector", '[data-testid="follow-toggle"]')) == 2, what="routes"
        )
        assert hint.text == "" and by_testid(browser, "follow-gain").get_attribute("disabled") is None
        with JackPlayer(n_ports=2, signal=step_signal()[int(QUIET_S * FS) :], name="follow-start") as player:
            player.connect(new_ports(before))
            player.play()
            wait_for(lambda: abs(served.get("intensity", 1) - knob_of(LOUD_DB)) < 0.05, what="channel 1 following")
        assert follow_get(served, "gain") == 0.0
        assert console_errors(browser) == []
    finally:
        browser.quit()
        served.stop()
