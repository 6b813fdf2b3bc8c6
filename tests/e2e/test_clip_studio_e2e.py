"""End to end in a browser: the studio's clip lane (issue 16, item 6).

``vibsynth serve`` (null output, a private user clip folder) serves the studio; headless
Chromium opens the Clips tab and works like a designer: picks a clip from the list, drags a
breakpoint, saves (the user file holds the new value), imports an AHAP file from the file
picker and a broken one (the error line says what is wrong and nothing is written), and plays
and stops the clip on the page's channel. The page is driven by its stable ``data-testid``s.

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_clip_studio_e2e.py -q``.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from tests.e2e.jackutil import e2e_required, stop_process
from tests.formats.haptic_samples import SPRING
from vibsynth.settings.clips import load_clip

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "clip-lane-e2e-token-0123456789"
START_TIMEOUT_S = 120.0
WAIT_S = 15.0


def _browser_or_skip():
    webdriver = pytest.importorskip("selenium.webdriver")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    driver_path = shutil.which("chromedriver")
    if not chromium or not driver_path:
        if e2e_required():
            pytest.fail("chromium and chromedriver are needed (scripts/setup.sh --test installs them)")
        pytest.skip("no chromium / chromedriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1400,1000"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(driver_path), options=options)


def _free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def service(tmp_path):
    clips = tmp_path / "clips"
    studio_port, osc_port = _free_port(), _free_port(socket.SOCK_DGRAM)
    config = tmp_path / "vibsynth.yaml"
    config.write_text(
        f"version: 1\nclips:\n  user_dir: {clips}\naudio:\n  rate: 8000\nbank:\n  levels: 9\n  loop_seconds: 1\n"
    )
    env = dict(
        os.environ,
        PYTHONPATH=str(ROOT),
        XDG_CONFIG_HOME=str(tmp_path / "cfg"),
        XDG_DATA_HOME=str(tmp_path / "data"),
        XDG_CACHE_HOME=str(tmp_path / "cache"),
    )
    cmd = [
        sys.executable,
        "-m",
        "vibsynth",
        "serve",
        "--config",
        str(config),
        "--output",
        "null",
        "--no-midi",
        "--osc-port",
        str(osc_port),
        "--studio-port",
        str(studio_port),
        "--studio-token",
        TOKEN,
        "--channels",
        "2",
    ]
    log_path = tmp_path / "serve.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{studio_port}"
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            raise AssertionError(f"serve exited ({proc.returncode}):\n{log_path.read_text()}")
        try:
            request = urllib.request.Request(f"{base}/api/state", headers={"Authorization": f"Bearer {TOKEN}"})
            with urllib.request.urlopen(request, timeout=1) as response:
                state = json.load(response)
            break
        except OSError:
            if time.monotonic() > deadline:
                proc.terminate()
                raise AssertionError("the studio did not answer in time:\n" + log_path.read_text()) from None
            time.sleep(0.2)
    yield base, clips, state, tmp_path
    stop_process(proc)


def _wait(browser, condition, what: str, timeout: float = WAIT_S):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(browser, timeout).until(lambda b: condition(b), message=f"waiting for {what}")


def _by(testid: str) -> tuple[str, str]:
    from selenium.webdriver.common.by import By

    return By.CSS_SELECTOR, f"[data-testid={testid}]"


def test_the_clip_lane_in_a_browser(service):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    base, clips, state, tmp_path = service
    assert {"name": "clips", "title": "Clips", "script": "/ext/clips/tab.js"} in state["extensions"]
    browser = _browser_or_skip()
    try:
        browser.get(f"{base}/?token={TOKEN}")
        _wait(browser, lambda b: b.find_elements(By.ID, "tab-clips"), "the Clips tab").__getitem__(0).click()
        items = _wait(browser, lambda b: b.find_elements(*_by("clip-item")), "the clip list")
        assert [i.get_attribute("data-name") for i in items] == [
            "gravel-steps",
            "heartbeat",
            "impact",
            "rain",
            "zipper",
        ]

        # open heartbeat: 7 keyframes x 2 curves, 2 transient markers
        next(i for i in items if i.get_attribute("data-name") == "heartbeat").click()
        _wait(browser, lambda b: b.find_element(*_by("clip-name")).get_attribute("value") == "heartbeat", "heartbeat")
        canvas = browser.find_element(*_by("clip-canvas"))
        points = canvas.find_elements(*_by("clip-point"))
        assert len(points) == 14 and len(canvas.find_elements(*_by("clip-transient"))) == 2

        # drag the second intensity breakpoint up: the clip is changed, then saved to the user folder
        point = next(
            p for p in points if p.get_attribute("data-kind") == "intensity" and p.get_attribute("data-index") == "1"
        )
        y0 = float(point.get_attribute("cy"))
        ActionChains(browser).move_to_element(point).click_and_hold().move_by_offset(0, -60).release().perform()
        moved = browser.find_element(By.CSS_SELECTOR, "[data-testid=clip-point][data-kind=intensity][data-index='1']")
        assert float(moved.get_attribute("cy")) < y0 - 20
        assert browser.find_element(*_by("clip-save")).text == "Save *"
        browser.find_element(*_by("clip-save")).click()
        _wait(browser, lambda b: (clips / "heartbeat.yaml").is_file(), "the saved file")
        saved = load_clip(clips / "heartbeat.yaml")
        assert saved.keyframes[1].intensity > 0.2 and saved.keyframes[0].intensity == 0.38  # only that point moved
        assert browser.find_element(*_by("clip-error")).text == ""

        # import an AHAP file through the file picker: shown unsaved, then saved under its name
        spring = tmp_path / "spring.ahap"
        spring.write_text(SPRING)
        browser.find_element(*_by("clip-import-file")).send_keys(str(spring))
        _wait(browser, lambda b: b.find_element(*_by("clip-name")).get_attribute("value") == "spring", "the import")
        assert (
            len(browser.find_elements(*_by("clip-point"))) == 2 * 3
            and len(browser.find_elements(*_by("clip-transient"))) == 1
        )
        assert not (clips / "spring.yaml").exists()
        browser.find_element(*_by("clip-save")).click()
        _wait(browser, lambda b: (clips / "spring.yaml").is_file(), "the imported clip's file")
        assert load_clip(clips / "spring.yaml").description == "a spring"
        _wait(
            browser,
            lambda b: "spring" in [i.get_attribute("data-name") for i in b.find_elements(*_by("clip-item"))],
            "spring in the list",
        )

        # a broken file: one clear error line, nothing written
        broken = tmp_path / "broken.ahap"
        broken.write_text('{"Version": 1, "Pattern": [{"Event": {"Time": 0.0, "EventType": "Hap')
        before = sorted(p.name for p in clips.iterdir())
        browser.find_element(*_by("clip-import-file")).send_keys(str(broken))
        error = _wait(browser, lambda b: b.find_element(*_by("clip-error")).text, "the error line")
        assert error.startswith("broken.ahap:1:") and "truncated" in error
        assert sorted(p.name for p in clips.iterdir()) == before

        # play and stop on the page's channel
        browser.find_element(*_by("clip-item")).click()  # gravel-steps (saved: no question asked)
        _wait(browser, lambda b: b.find_element(*_by("clip-name")).get_attribute("value") == "gravel-steps", "gravel")
        browser.find_element(*_by("clip-loop")).click()
        browser.find_element(*_by("clip-play")).click()
        assert _player_runs(base)
        _wait(browser, lambda b: _playing(base, 1) == "gravel-steps", "the clip playing on channel 1")
        head = browser.find_element(*_by("clip-playhead"))
        _wait(browser, lambda b: float(head.get_attribute("x1")) > 0, "the playhead moving")
        _wait(browser, lambda b: _driver(base, 1) == "clip", "the clip driving channel 1's knobs")
        assert _driver(base, 2) == "knobs"  # only the page's channel
        browser.find_element(*_by("clip-stop")).click()
        _wait(browser, lambda b: _playing(base, 1) is None, "the channel released")
        _wait(browser, lambda b: _driver(base, 1) == "knobs", "channel 1 back to its knobs")
        assert browser.find_element(*_by("clip-error")).text == ""
    finally:
        browser.quit()


def _get(base: str, path: str):
    request = urllib.request.Request(f"{base}{path}", headers={"Authorization": f"Bearer {TOKEN}"})
    with urllib.request.urlopen(request, timeout=5) as response:
        return json.load(response)


def _player_runs(base: str) -> bool:
    return bool(_get(base, "/ext/clips/list")["playing"])


def _playing(base: str, channel: int):
    now = _get(base, f"/ext/clips/playing?channel={channel}")["playing"]
    return None if now is None else now["name"]


def _driver(base: str, channel: int) -> str:
    return str(_get(base, "/api/state")["state"][channel - 1]["driver"])
