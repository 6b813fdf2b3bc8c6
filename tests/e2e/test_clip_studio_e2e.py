"""End to end in a browser: the studio's clip lane (issue 16, item 6).

``vibsynth serve`` (null output, a private user clip folder) serves the studio; headless
Chromium opens the Clips tab and works like a designer: picks a clip from the list, drags a
breakpoint, saves (the user file holds the new value), imports an AHAP file from the file
picker and a broken one (the error line says what is wrong and nothing is written), and plays
and stops the clip on the page's channel. The page is driven by its stable ``data-testid``s.

Run: ``scripts/with_jack.sh -- python -m pytest tests/e2e/test_clip_studio_e2e.py -q``.
"""

from __future__ import annotations

import pytest

from tests.e2e.studioutil import Served, by, chromium_or_skip, require_browser, start_serve, wait
from tests.formats.haptic_samples import SPRING
from vibsynth.settings.clips import load_clip

#: Runs on the unit tests' workers (tests/e2e/conftest.py): serve on the null output, a browser page; no time measured.
PARALLEL_SAFE = True

pytestmark = pytest.mark.e2e


@pytest.fixture
def service(tmp_path):
    require_browser()
    clips = tmp_path / "clips"
    config = f"clips:\n  user_dir: {clips}\nbank:\n  levels: 9\n  loop_seconds: 1\n"
    served = start_serve(tmp_path / "serve", channels=2, rate=8000, extra_config=config)
    yield served, clips, tmp_path
    served.stop()


def test_the_clip_lane_in_a_browser(service):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    served, clips, tmp_path = service
    assert {"name": "clips", "title": "Clips", "script": "/ext/clips/tab.js"} in served.api("/api/state")["extensions"]
    browser = chromium_or_skip(1400, 1000)
    try:
        browser.get(served.url)
        wait(browser, lambda b: b.find_elements(By.ID, "tab-clips"), "the Clips tab").__getitem__(0).click()
        items = wait(browser, lambda b: b.find_elements(*by("clip-item")), "the clip list")
        assert [i.get_attribute("data-name") for i in items] == [
            "gravel-steps",
            "heartbeat",
            "impact",
            "rain",
            "zipper",
        ]

        # open heartbeat: 7 keyframes x 2 curves, 2 transient markers
        next(i for i in items if i.get_attribute("data-name") == "heartbeat").click()
        wait(browser, lambda b: b.find_element(*by("clip-name")).get_attribute("value") == "heartbeat", "heartbeat")
        canvas = browser.find_element(*by("clip-canvas"))
        points = canvas.find_elements(*by("clip-point"))
        assert len(points) == 14 and len(canvas.find_elements(*by("clip-transient"))) == 2

        # drag the second intensity breakpoint up: the clip is changed, then saved to the user folder
        point = next(
            p for p in points if p.get_attribute("data-kind") == "intensity" and p.get_attribute("data-index") == "1"
        )
        y0 = float(point.get_attribute("cy"))
        ActionChains(browser).move_to_element(point).click_and_hold().move_by_offset(0, -60).release().perform()
        moved = browser.find_element(By.CSS_SELECTOR, "[data-testid=clip-point][data-kind=intensity][data-index='1']")
        assert float(moved.get_attribute("cy")) < y0 - 20
        assert browser.find_element(*by("clip-save")).text == "Save *"
        browser.find_element(*by("clip-save")).click()
        wait(browser, lambda b: (clips / "heartbeat.yaml").is_file(), "the saved file")
        saved = load_clip(clips / "heartbeat.yaml")
        assert saved.keyframes[1].intensity > 0.2 and saved.keyframes[0].intensity == 0.38  # only that point moved
        assert browser.find_element(*by("clip-error")).text == ""

        # import an AHAP file through the file picker: shown unsaved, then saved under its name
        spring = tmp_path / "spring.ahap"
        spring.write_text(SPRING)
        browser.find_element(*by("clip-import-file")).send_keys(str(spring))
        wait(browser, lambda b: b.find_element(*by("clip-name")).get_attribute("value") == "spring", "the import")
        assert (
            len(browser.find_elements(*by("clip-point"))) == 2 * 3
            and len(browser.find_elements(*by("clip-transient"))) == 1
        )
        assert not (clips / "spring.yaml").exists()
        browser.find_element(*by("clip-save")).click()
        wait(browser, lambda b: (clips / "spring.yaml").is_file(), "the imported clip's file")
        assert load_clip(clips / "spring.yaml").description == "a spring"
        wait(
            browser,
            lambda b: "spring" in [i.get_attribute("data-name") for i in b.find_elements(*by("clip-item"))],
            "spring in the list",
        )

        # a broken file: one clear error line, nothing written
        broken = tmp_path / "broken.ahap"
        broken.write_text('{"Version": 1, "Pattern": [{"Event": {"Time": 0.0, "EventType": "Hap')
        before = sorted(p.name for p in clips.iterdir())
        browser.find_element(*by("clip-import-file")).send_keys(str(broken))
        error = wait(browser, lambda b: b.find_element(*by("clip-error")).text, "the error line")
        assert error.startswith("broken.ahap:1:") and "truncated" in error
        assert sorted(p.name for p in clips.iterdir()) == before

        # play and stop on the page's channel
        browser.find_element(*by("clip-item")).click()  # gravel-steps (saved: no question asked)
        wait(browser, lambda b: b.find_element(*by("clip-name")).get_attribute("value") == "gravel-steps", "gravel")
        browser.find_element(*by("clip-loop")).click()
        browser.find_element(*by("clip-play")).click()
        assert _player_runs(served)
        wait(browser, lambda b: _playing(served, 1) == "gravel-steps", "the clip playing on channel 1")
        head = browser.find_element(*by("clip-playhead"))
        wait(browser, lambda b: float(head.get_attribute("x1")) > 0, "the playhead moving")
        wait(browser, lambda b: _driver(served, 1) == "clip", "the clip driving channel 1's knobs")
        assert _driver(served, 2) == "knobs"  # only the page's channel
        browser.find_element(*by("clip-stop")).click()
        wait(browser, lambda b: _playing(served, 1) is None, "the channel released")
        wait(browser, lambda b: _driver(served, 1) == "knobs", "channel 1 back to its knobs")
        assert browser.find_element(*by("clip-error")).text == ""
    finally:
        browser.quit()


def _player_runs(served: Served) -> bool:
    return bool(served.api("/ext/clips/list")["playing"])


def _playing(served: Served, channel: int):
    now = served.api(f"/ext/clips/playing?channel={channel}")["playing"]
    return None if now is None else now["name"]


def _driver(served: Served, channel: int) -> str:
    return str(served.api("/api/state")["state"][channel - 1]["driver"])
