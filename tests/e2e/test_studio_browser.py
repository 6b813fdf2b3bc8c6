"""The studio in a real browser: headless Chromium (Selenium) against a real ``vibsynth serve``.

One service (null output, two channels, a private user preset folder) and one browser for
the module. The page is loaded with the token the service printed; sliders, the XY pad and
the buttons are moved with the mouse and the keyboard, and the engine's knobs are read back
over OSC; OSC moves must show on the page; presets are saved, edited and deleted through the
form; a texture recording made from ../shared is uploaded; requests without the token and
from a foreign origin are refused. Every wait is an explicit wait on a condition.

The keyboard: a focused slider moves by 1 % of its range per arrow key and 10 % with Page
Up/Down or Shift+arrow, whatever its drag resolution (``step``, 0.001 of the intensity, which a
drag keeps); the XY pad the same on its two axes. Save as on a fresh page saves the knobs that
play, as ``vibsynth preset show`` reads them back.

The run writes a screenshot (``studio.png`` in the test's folder, and to
``$VIBSYNTH_STUDIO_SCREENSHOT`` when set: docs/images/studio.png comes from there).

Run: ``python -m pytest tests/e2e/test_studio_browser.py -q``.
"""

from __future__ import annotations

import http.server
import json
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import vibsynth
from tests.control.studio.helpers import texture_recording
from tests.e2e.studioutil import (
    ROOT,
    Served,
    by_testid,
    chromium,
    console_errors,
    open_studio,
    require_browser,
    start_serve,
    wait_for,
)
from vibsynth.control.studio.spectrum import SpectrumModel
from vibsynth.settings.presets import load_preset

#: Runs on the unit tests' workers (tests/e2e/conftest.py): serve on the null output, a browser page; no time measured.
PARALLEL_SAFE = True

pytestmark = pytest.mark.e2e

TOLERANCE = 1e-5  # OSC sends float32


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    require_browser()
    service = start_serve(tmp_path_factory.mktemp("studio-e2e"))
    yield service
    service.stop()


@pytest.fixture(scope="module")
def driver(served):
    browser = chromium()
    yield browser
    browser.quit()


@pytest.fixture
def page(driver, served):
    console_errors(driver)  # drain what earlier tests left (refusals are expected there)
    open_studio(driver, served)
    yield driver
    assert console_errors(driver) == []


def close(a: float, b: float, tol: float = TOLERANCE) -> bool:
    return abs(float(a) - float(b)) <= tol


# ---------------------------------------------------------------------------------- security
def test_without_the_token_the_page_is_refused(driver, served):
    from selenium.webdriver.common.by import By

    driver.delete_all_cookies()
    driver.get(served.base + "/")
    body = driver.find_element(By.TAG_NAME, "body").text
    assert "forbidden: no valid studio token" in body
    driver.get(served.base + "/?token=" + "x" * len(served.token))
    assert "forbidden" in driver.find_element(By.TAG_NAME, "body").text
    assert served.api("/api/status")["studio"]["refused"]["token"] >= 2


def test_a_foreign_origin_cannot_drive_the_engine_or_write_files(driver, served, tmp_path):
    """A page of another origin (another port of 127.0.0.1: the same site, so the cookie goes along)."""
    open_studio(driver, served)  # the browser holds the cookie now
    before = served.api("/api/status")["studio"]["refused"].get("origin", 0)
    intensity = served.get("intensity")
    (tmp_path / "evil.html").write_text(
        "<!doctype html><p id=ws>pending</p><p id=post>pending</p><script>\n"
        f"const studio = '{served.base}';\n"
        "const ws = new WebSocket(studio.replace('http', 'ws') + '/ws');\n"
        "ws.onopen = () => { ws.send(JSON.stringify({type: 'knob', name: 'intensity', value: 1})); "
        "document.getElementById('ws').textContent = 'open'; };\n"
        "ws.onclose = (e) => { if (document.getElementById('ws').textContent === 'pending') "
        "document.getElementById('ws').textContent = 'refused ' + e.code; };\n"
        "fetch(studio + '/api/presets', {method: 'POST', mode: 'no-cors', credentials: 'include', "
        "headers: {'Content-Type': 'text/plain'}, body: JSON.stringify({name: 'evil', intensity: 1, balance: 0})})"
        ".then(() => { document.getElementById('post').textContent = 'sent'; })"
        ".catch(() => { document.getElementById('post').textContent = 'failed'; });\n"
        "</script>\n"
    )
    handler = lambda *a: http.server.SimpleHTTPRequestHandler(*a, directory=str(tmp_path))  # noqa: E731
    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=evil.serve_forever, daemon=True)
    thread.start()
    try:
        from selenium.webdriver.common.by import By

        driver.get(f"http://127.0.0.1:{evil.server_address[1]}/evil.html")
        wait_for(lambda: driver.find_element(By.ID, "ws").text.startswith("refused"), what="the WebSocket refusal")
        wait_for(lambda: driver.find_element(By.ID, "post").text != "pending", what="the POST to finish")
        wait_for(
            lambda: served.api("/api/status")["studio"]["refused"].get("origin", 0) >= before + 2,
            what="both refusals counted",
        )
    finally:
        evil.shutdown()
        evil.server_close()
    assert served.get("intensity") == intensity
    assert not (served.user_dir / "evil.yaml").exists()


# ---------------------------------------------------------------------------------- knobs
def test_sliders_pad_and_buttons_drive_the_engine(page, served):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    intensity = by_testid(page, "intensity")
    balance = by_testid(page, "balance")
    # the mouse: click 30 % along the intensity slider
    width = intensity.size["width"]
    ActionChains(page).move_to_element_with_offset(intensity, int(-width * 0.2), 0).click().perform()
    value = float(intensity.get_attribute("value"))
    assert 0.1 < value < 0.5
    wait_for(lambda: close(served.get("intensity"), value), what=f"the engine's intensity to reach {value}")
    assert by_testid(page, "intensity-value").text == f"{value:.3f}"
    # the keyboard: End / Home / arrows on the balance slider
    balance.send_keys(Keys.END)
    wait_for(lambda: close(served.get("balance"), 3.5), what="balance 3.5 (End)")
    balance.send_keys(Keys.HOME)
    wait_for(lambda: close(served.get("balance"), -3.5), what="balance -3.5 (Home)")
    balance.send_keys(Keys.ARROW_RIGHT, Keys.ARROW_RIGHT)  # 1 % of the range each (test_studio_keys_e2e.py)
    wait_for(lambda: close(served.get("balance"), -3.36), what="two steps right")
    assert by_testid(page, "balance-value").text == "-3.360"
    # channel 2 is its own
    assert close(served.get("intensity", channel=2), 0.0)
    # the XY pad: the top-right corner region is loud and bright
    pad = by_testid(page, "xy-pad")
    ActionChains(page).move_to_element_with_offset(
        pad, int(pad.size["width"] * 0.3), int(-pad.size["height"] * 0.3)
    ).click().perform()
    i, b = float(intensity.get_attribute("value")), float(balance.get_attribute("value"))
    assert 0.7 < i < 0.9 and 1.5 < b < 2.8
    wait_for(lambda: close(served.get("intensity"), i) and close(served.get("balance"), b), what="the pad's texture")
    pad.send_keys(Keys.ARROW_DOWN)  # keyboard on the pad: 0.01 less intensity
    wait_for(lambda: close(served.get("intensity"), round(i - 0.01, 3)), what="the pad's arrow key")
    # glide, mute, panic
    glide = by_testid(page, "glide")
    glide.clear()
    glide.send_keys("250", Keys.TAB)
    wait_for(lambda: close(served.get("glide"), 250.0, 1e-3), what="glide 250 ms")
    mute = by_testid(page, "mute")
    mute.click()
    wait_for(lambda: served.get("mute") == 1, what="mute")
    wait_for(lambda: mute.get_attribute("aria-pressed") == "true", what="the mute button pressed")
    mute.click()
    wait_for(lambda: served.get("mute") == 0, what="unmute")
    by_testid(page, "panic").click()
    wait_for(lambda: close(served.get("intensity"), 0.0) and close(served.get("intensity", 2), 0.0), what="panic")
    wait_for(lambda: by_testid(page, "intensity-value").text == "0.000", what="the page after panic")


def press(page, served, testid: str, keys: str, expected: float, knob: str | None = None) -> None:
    """Send keys to a focused control; the slider, its number and the engine's knob must show ``expected``."""
    element = by_testid(page, testid)
    element.send_keys(keys)
    knob = knob or testid
    wait_for(lambda: close(by_testid(page, knob).get_attribute("value"), expected, 1e-9), what=f"{knob} at {expected}")
    shown = f"{expected:.3f}" if knob == "intensity" else f"{'+' if expected >= 0 else ''}{expected:.3f}"
    assert by_testid(page, f"{knob}-value").text == shown
    wait_for(lambda: close(served.get(knob), expected), what=f"the engine's {knob} at {expected}")


def test_the_sliders_move_1_percent_per_arrow_and_10_percent_with_page_or_shift(page, served):
    from selenium.webdriver.common.keys import Keys

    intensity = by_testid(page, "intensity")
    assert intensity.get_attribute("step") == "0.001"  # the drag resolution is kept
    press(page, served, "intensity", Keys.HOME, 0.0)
    press(page, served, "intensity", Keys.ARROW_RIGHT, 0.01)
    press(page, served, "intensity", Keys.ARROW_UP * 2, 0.03)
    press(page, served, "intensity", Keys.PAGE_UP, 0.13)
    press(page, served, "intensity", Keys.SHIFT + Keys.ARROW_RIGHT + Keys.NULL, 0.23)
    press(page, served, "intensity", Keys.SHIFT + Keys.ARROW_UP + Keys.NULL, 0.33)
    press(page, served, "intensity", Keys.ARROW_LEFT, 0.32)
    press(page, served, "intensity", Keys.PAGE_DOWN, 0.22)
    press(page, served, "intensity", Keys.SHIFT + Keys.ARROW_DOWN + Keys.NULL, 0.12)
    press(page, served, "intensity", Keys.PAGE_DOWN * 3, 0.0)  # kept at the end
    press(page, served, "intensity", Keys.END, 1.0)
    press(page, served, "intensity", Keys.ARROW_RIGHT, 1.0)
    # balance (the live range -3.5..+3.5): end to end in 100 arrow presses, or 10 page presses
    press(page, served, "balance", Keys.HOME, -3.5)
    press(page, served, "balance", Keys.ARROW_RIGHT, -3.43)
    press(page, served, "balance", Keys.ARROW_RIGHT * 49, 0.0)
    press(page, served, "balance", Keys.ARROW_RIGHT * 50, 3.5)
    press(page, served, "balance", Keys.PAGE_DOWN * 10, -3.5)
    press(page, served, "balance", Keys.SHIFT + Keys.ARROW_RIGHT * 3 + Keys.NULL, -1.4)
    press(page, served, "balance", Keys.ARROW_LEFT, -1.47)
    # the other channel is not touched
    assert close(served.get("balance", channel=2), 0.0)


def test_a_drag_keeps_its_fine_resolution(page, served):
    """A drag of one pixel moves the slider less than one arrow step (the keys do not coarsen drags)."""
    from selenium.webdriver.common.action_chains import ActionChains

    intensity = by_testid(page, "intensity")
    width = intensity.size["width"]
    assert width >= 150, width  # 1 px < 1 % of the range
    x = -int(width * 0.2)  # from the slider's centre
    ActionChains(page).move_to_element_with_offset(intensity, x, 0).click().perform()
    before = float(intensity.get_attribute("value"))
    ActionChains(page).move_to_element_with_offset(intensity, x, 0).click_and_hold().move_to_element_with_offset(
        intensity, x + 1, 0
    ).release().perform()
    after = float(intensity.get_attribute("value"))
    assert 0 < after - before < 0.01, (before, after)
    wait_for(lambda: close(served.get("intensity"), after), what="the dragged intensity")


def test_the_pad_takes_the_same_steps(page, served):
    from selenium.webdriver.common.keys import Keys

    press(page, served, "intensity", Keys.HOME, 0.0)
    press(page, served, "balance", Keys.HOME, -3.5)
    press(page, served, "xy-pad", Keys.ARROW_RIGHT, -3.43, knob="balance")
    press(page, served, "xy-pad", Keys.SHIFT + Keys.ARROW_RIGHT + Keys.NULL, -2.73, knob="balance")
    press(page, served, "xy-pad", Keys.ARROW_UP, 0.01, knob="intensity")
    press(page, served, "xy-pad", Keys.PAGE_UP, 0.11, knob="intensity")
    press(page, served, "xy-pad", Keys.SHIFT + Keys.ARROW_DOWN + Keys.NULL, 0.01, knob="intensity")
    press(page, served, "xy-pad", Keys.ARROW_LEFT, -2.8, knob="balance")


def test_osc_moves_show_on_the_page_with_their_spectrum(page, served, basis):
    served.osc.send("/vibsynth/ch/1/texture", 0.62, -1.2)
    wait_for(lambda: by_testid(page, "intensity-value").text == "0.620", what="intensity 0.620 on the page")
    wait_for(lambda: by_testid(page, "balance-value").text == "-1.200", what="balance -1.200 on the page")
    assert close(float(by_testid(page, "intensity").get_attribute("value")), 0.62, 1e-3)
    assert close(float(by_testid(page, "balance").get_attribute("value")), -1.2, 1e-3)
    # the other channel's move does not touch the page's channel
    served.osc.send("/vibsynth/ch/2/intensity", 0.9)
    served.osc.send("/vibsynth/ch/1/balance", -1.0)
    wait_for(lambda: by_testid(page, "balance-value").text == "-1.000", what="balance -1.000")
    assert by_testid(page, "intensity-value").text == "0.620"
    # the spectrum: the model's target at these knobs, and the measured output near it
    model = SpectrumModel(basis, fs=48000.0, ceiling_db=-40.0, range_db=40.0)
    expected = model.target_db(0.62, -1.0)
    spectrum = by_testid(page, "spectrum")

    def target_shown() -> bool:
        values = json.loads(spectrum.get_attribute("data-target-db"))
        return len(values) == 30 and np.allclose(values, expected, atol=0.011)

    wait_for(target_shown, what="the target spectrum of (0.62, -1.0)")

    def measured_near_target() -> bool:
        values = json.loads(spectrum.get_attribute("data-measured-db"))
        if len(values) != 30 or None in values:
            return False
        centres = model.centres_hz
        high = np.asarray(values)[centres >= 100.0] - expected[centres >= 100.0]
        return bool(np.max(np.abs(high)) < 2.0)

    wait_for(measured_near_target, timeout=20, what="the measured output spectrum near the target from 100 Hz up")
    # the channel selector shows channel 2's knobs
    from selenium.webdriver.support.select import Select

    Select(by_testid(page, "channel")).select_by_value("2")
    wait_for(lambda: by_testid(page, "intensity-value").text == "0.900", what="channel 2's intensity")
    Select(by_testid(page, "channel")).select_by_value("1")
    wait_for(lambda: by_testid(page, "intensity-value").text == "0.620", what="channel 1's intensity again")


# ---------------------------------------------------------------------------------- presets
def preset_names(page) -> list[str]:
    """The names in the list, read in one go (the list is redrawn when the library changes)."""
    return page.execute_script(
        "return [...document.querySelectorAll('[data-testid=\"preset-item\"]')].map((e) => e.dataset.name)"
    )


def click_preset(page, name: str) -> None:
    """Click a preset of the list (again if it was redrawn between finding and clicking it)."""
    from selenium.webdriver.common.by import By

    selector = f'[data-testid="preset-item"][data-name="{name}"]'
    wait_for(lambda: page.find_element(By.CSS_SELECTOR, selector).click() or True, what=f"clicking {name}")


def preset_show(served: Served, name: str) -> dict:
    """``vibsynth preset show NAME --json`` with the service's config: what the command line loads."""
    folder = served.log.parent
    env = dict(
        os.environ,
        PYTHONPATH=str(ROOT),
        XDG_CONFIG_HOME=str(folder / "xdg-config"),
        XDG_DATA_HOME=str(folder / "xdg-data"),
    )
    command = [
        sys.executable,
        "-m",
        "vibsynth",
        "preset",
        "show",
        name,
        "--json",
        "--config",
        str(folder / "vibsynth.yaml"),
    ]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_save_as_on_a_fresh_page_saves_the_sound_that_plays(page, served):
    """Open the studio, move the knobs, type a name, Save: the preset is what was heard (issue 26)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    intensity = by_testid(page, "intensity")
    balance = by_testid(page, "balance")
    ActionChains(page).move_to_element_with_offset(intensity, int(intensity.size["width"] * 0.15), 0).click().perform()
    ActionChains(page).move_to_element_with_offset(balance, -int(balance.size["width"] * 0.3), 0).click().perform()
    i, b = float(intensity.get_attribute("value")), float(balance.get_attribute("value"))
    assert 0.5 < i < 0.8 and -3.0 < b < -1.0
    wait_for(lambda: close(served.get("intensity"), i) and close(served.get("balance"), b), what="the knobs moved")
    # the form shows the knobs (it follows them until a field is typed in or a preset picked)
    field_i = page.find_element(By.ID, "preset-field-intensity")
    field_b = page.find_element(By.ID, "preset-field-balance")
    wait_for(
        lambda: (float(field_i.get_attribute("value")), float(field_b.get_attribute("value"))) == (i, b),
        what="the form showing the knobs",
    )
    assert "follow the knobs of channel 1" in by_testid(page, "preset-follow").text
    name = by_testid(page, "preset-save-name")
    name.send_keys("e2e-heard")
    by_testid(page, "preset-save").click()
    wait_for(lambda: "saved e2e-heard" in page.find_element(By.ID, "preset-note").text, what="the saved note")
    assert by_testid(page, "preset-error").text == ""
    shown = preset_show(served, "e2e-heard")
    assert (shown["intensity"], shown["balance"]) == (i, b), shown
    assert close(served.get("intensity"), shown["intensity"]) and close(served.get("balance"), shown["balance"])
    assert shown["provenance"]["from_knobs"] == {"channel": 1, "keys": ["intensity", "balance"]}
    # the form keeps following: a new move, Save again, and the preset is the new sound
    wait_for(lambda: "e2e-heard" in preset_names(page), what="the new preset in the list")
    balance.send_keys(Keys.END)
    wait_for(lambda: close(served.get("balance"), 3.5), what="balance 3.5")
    wait_for(lambda: float(field_b.get_attribute("value")) == 3.5, what="the form following the move")
    by_testid(page, "preset-save").click()
    wait_for(lambda: preset_show(served, "e2e-heard")["balance"] == 3.5, what="the preset replaced by the new sound")
    assert preset_show(served, "e2e-heard")["intensity"] == i
    # a value typed in the form wins over the knobs; the other field still follows them
    field_i.clear()
    field_i.send_keys("0.25")
    name.clear()
    name.send_keys("e2e-typed")
    by_testid(page, "preset-save").click()
    wait_for(lambda: (served.user_dir / "e2e-typed.yaml").exists(), what="the second preset")
    typed = preset_show(served, "e2e-typed")
    assert (typed["intensity"], typed["balance"]) == (0.25, 3.5)
    assert typed["provenance"]["from_knobs"] == {"channel": 1, "keys": ["balance"]}


def test_filter_audition_save_edit_and_delete_presets(page, served):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    wait_for(lambda: "brick" in preset_names(page), what="the preset list")
    all_names = preset_names(page)
    by_testid(page, "preset-filter").send_keys("stone")
    wait_for(lambda: preset_names(page) and len(preset_names(page)) < len(all_names), what="the filter")
    assert "brick" in preset_names(page)
    by_testid(page, "preset-filter").send_keys(Keys.CONTROL, "a", Keys.BACKSPACE)
    wait_for(lambda: len(preset_names(page)) == len(all_names), what="the whole list again")
    # audition: the engine glides to the shipped preset
    click_preset(page, "brick")
    brick = served.api("/api/presets")
    brick = next(p for p in brick["presets"] if p["name"] == "brick")
    wait_for(lambda: served.get("preset") == "brick", what="brick to play")
    assert close(served.get("intensity"), brick["intensity"]) and close(served.get("balance"), brick["balance"])
    assert by_testid(page, "preset-delete").get_attribute("disabled") == "true"  # shipped: read-only
    # save as a new user preset, with a changed intensity
    field = page.find_element(By.ID, "preset-field-intensity")
    field.clear()
    field.send_keys("0.42")
    name = by_testid(page, "preset-save-name")
    name.clear()
    name.send_keys("e2e-mine")
    by_testid(page, "preset-save").click()
    path = served.user_dir / "e2e-mine.yaml"
    wait_for(path.exists, what="the preset file")
    saved = load_preset(path)
    assert (saved.intensity, saved.balance) == (0.42, brick["balance"])
    assert saved.provenance["edited_from"] == "brick"
    wait_for(lambda: "e2e-mine" in preset_names(page), what="the new preset in the list")
    # a wrong value: the error is named beside its field, nothing is written
    balance = page.find_element(By.ID, "preset-field-balance")
    balance.clear()
    balance.send_keys("9")
    by_testid(page, "preset-save").click()
    wait_for(lambda: "outside the allowed range [-4, 4]" in by_testid(page, "preset-error").text, what="the error")
    assert "outside the allowed range" in page.find_element(By.ID, "preset-field-balance-error").text
    assert balance.get_attribute("aria-invalid") == "true"
    assert load_preset(path).balance == brick["balance"]
    # a name that is not a plain file name
    name.clear()
    name.send_keys("../x")
    by_testid(page, "preset-save").click()
    wait_for(lambda: "letters, digits" in by_testid(page, "preset-error").text, what="the name error")
    assert not (served.user_dir.parent / "x.yaml").exists()
    # edit in place: select it, change the intensity, save
    click_preset(page, "e2e-mine")
    field = page.find_element(By.ID, "preset-field-intensity")
    field.clear()
    field.send_keys("0.55")
    by_testid(page, "preset-save").click()
    wait_for(lambda: load_preset(path).intensity == 0.55, what="the edit on disk")
    # a file written by hand appears (hot reload)
    (served.user_dir / "by-hand.yaml").write_text("version: 1\nintensity: 0.3\nbalance: 2\ntags: [hand]\n")
    wait_for(lambda: "by-hand" in preset_names(page), what="the hand-written preset")
    # delete (two clicks: the first asks)
    click_preset(page, "e2e-mine")
    delete = by_testid(page, "preset-delete")
    delete.click()
    wait_for(lambda: "Click again" in delete.text, what="the delete confirmation")
    assert path.exists()
    delete.click()
    wait_for(lambda: not path.exists(), what="the file removed")
    wait_for(lambda: "e2e-mine" not in preset_names(page), what="the preset gone from the list")


# ---------------------------------------------------------------------------------- recording
@pytest.mark.shared
def test_upload_a_texture_recording_and_make_a_preset(page, served, hatt_psd, tmp_path):
    from selenium.webdriver.common.by import By

    recording = tmp_path / "Brick 1.wav"
    expected = texture_recording(recording, hatt_psd, "Brick 1")
    reference = vibsynth.analyze(recording)
    by_testid(page, "recording-file").send_keys(str(recording))
    balance = f"{'+' if reference.balance >= 0 else ''}{reference.balance:.3f}"
    wait_for(lambda: by_testid(page, "recording-balance").text.startswith(balance), what=f"balance {balance}")
    assert abs(reference.balance - expected["balance"]) < 0.15
    intensity = by_testid(page, "recording-intensity")
    assert close(float(intensity.get_attribute("data-value")), round(reference.intensity_knob, 4), 1e-9)
    assert page.find_element(By.ID, "recording-stationary").get_attribute("data-stationary") == "true"
    assert page.find_element(By.ID, "recording-scores").text.startswith(f"t1 {reference.scores[0]:.2f}")
    name = page.find_element(By.ID, "recording-name")
    assert name.get_attribute("value") == "Brick-1"
    name.clear()
    name.send_keys("e2e-brick")
    by_testid(page, "recording-make-preset").click()
    path = served.user_dir / "e2e-brick.yaml"
    wait_for(path.exists, what="the preset made from the recording")
    preset = load_preset(path)
    assert preset.balance == round(reference.balance, 4)
    assert preset.provenance["recording"] == "Brick 1.wav"
    wait_for(lambda: "e2e-brick" in preset_names(page), what="the new preset in the list")


# ---------------------------------------------------------------------------------- status + screenshot
def test_status_and_midi_learn(page, served):
    from selenium.webdriver.common.by import By

    wait_for(lambda: by_testid(page, "status-state").text == "null", what="the output state")
    wait_for(lambda: by_testid(page, "status-underflows").text.isdigit(), what="the underflow count")
    assert "no MIDI input" in page.find_element(By.ID, "status-midi").text
    by_testid(page, "learn-intensity").click()
    wait_for(lambda: "MIDI learn unavailable" in page.find_element(By.ID, "learn-note").text, what="learn's answer")
    by_testid(page, "learn-balance").click()
    wait_for(lambda: "MIDI learn unavailable" in page.find_element(By.ID, "learn-note").text, what="learn's answer")
    assert page.find_element(By.ID, "knob-error").text == ""  # answered in the status panel only


@pytest.mark.shared
def test_a_screenshot_of_a_designers_session(page, served, hatt_psd, tmp_path, basis):
    """Everything in use: a preset auditioned then moved, its spectrum measured, a recording analysed."""
    recording = tmp_path / "Brick 1.wav"
    texture_recording(recording, hatt_psd, "Brick 1")
    click_preset(page, "brick")
    served.osc.send("/vibsynth/ch/1/texture", 0.7, 0.8)
    wait_for(lambda: by_testid(page, "balance-value").text == "+0.800", what="the texture for the picture")
    by_testid(page, "recording-file").send_keys(str(recording))
    wait_for(lambda: by_testid(page, "recording-balance").text != "", what="the recording's analysis")
    model = SpectrumModel(basis, fs=48000.0, ceiling_db=-40.0, range_db=40.0)
    expected = model.target_db(0.7, 0.8)

    def measured_near_target() -> bool:
        values = json.loads(by_testid(page, "spectrum").get_attribute("data-measured-db"))
        if len(values) != 30 or None in values:
            return False
        return bool(np.max(np.abs(np.asarray(values) - expected)[model.centres_hz >= 100.0]) < 2.0)

    wait_for(measured_near_target, timeout=20, what="the measured spectrum of the new texture")
    page.set_window_size(1400, 1700)
    shot = tmp_path / "studio.png"
    page.save_screenshot(str(shot))
    assert shot.stat().st_size > 50_000
    target = os.environ.get("VIBSYNTH_STUDIO_SCREENSHOT")
    if target:
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, target)
