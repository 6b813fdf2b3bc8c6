"""A real ``vibsynth serve`` with its studio, and a headless Chromium driven by Selenium (e2e tests, benchmarks).

Chromium and chromedriver are Debian's (``scripts/setup.sh --test`` installs them):
``/usr/bin/chromium`` and ``/usr/bin/chromedriver``. Every wait is an explicit wait on a
condition with a deadline (:func:`wait_for`), never a sleep.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from tests.e2e.oscclient import OscClient

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = os.environ.get("VIBSYNTH_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("VIBSYNTH_CHROMEDRIVER", "/usr/bin/chromedriver")

T = TypeVar("T")


def browser_available() -> tuple[bool, str]:
    """(usable, reason): Chromium, chromedriver and Selenium are installed."""
    for path in (CHROMIUM, CHROMEDRIVER):
        if not (Path(path).is_file() or shutil.which(path)):
            return False, f"{path} is missing (scripts/setup.sh --test installs chromium and chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return False, "selenium is not installed (pip install -e '.[test]')"
    return True, ""


def wait_for(condition: Callable[[], T], *, timeout: float = 15.0, what: str = "a condition") -> T:
    """Poll ``condition`` until it returns something truthy (returned) or raise after ``timeout`` s.

    Exceptions raised by ``condition`` count as "not yet" (the page may be mid-update); the
    last one is shown when the deadline passes.
    """
    deadline = time.monotonic() + timeout
    last: BaseException | None = None
    while True:
        try:
            value = condition()
            if value:
                return value
        except Exception as exc:  # noqa: BLE001 - not ready yet
            last = exc
        if time.monotonic() > deadline:
            raise AssertionError(
                f"timed out after {timeout:g} s waiting for {what}" + (f" (last: {last!r})" if last else "")
            )
        time.sleep(0.02)


@dataclass
class Served:
    """A running ``vibsynth serve`` with its studio."""

    proc: subprocess.Popen[bytes]
    osc_port: int
    url: str
    token: str
    log: Path
    user_dir: Path
    osc: OscClient = field(init=False)

    def __post_init__(self) -> None:
        self.osc = OscClient(self.osc_port)

    @property
    def base(self) -> str:
        """``http://127.0.0.1:PORT`` (no token)."""
        return self.url.split("/?", 1)[0]

    def get(self, name: str, channel: int = 1) -> Any:
        """A knob of a channel as the engine's controller holds it (OSC ``get``)."""
        msg = self.osc.request(f"/vibsynth/ch/{channel}/get", name, expect=f"/vibsynth/ch/{channel}/{name}")
        return msg.args[0]

    def api(self, path: str, method: str = "GET", body: Any = None) -> Any:
        """A studio API call with the token as a Bearer header (a script, not the browser)."""
        import urllib.request

        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(
            self.base + path,
            data=data,
            method=method,
            headers={"Authorization": f"Bearer {self.token}", "Content-Type": "application/json"},
        )
        with urllib.request.urlopen(request, timeout=10) as response:
            return json.loads(response.read())

    def stop(self) -> None:
        from tests.e2e.test_osc_e2e import stop_serve

        self.osc.close()
        stop_serve(self.proc)


def start_serve(
    folder: Path, *, channels: int = 2, output: str = "null", rate: int | None = None, extra_config: str = ""
) -> Served:
    """Start ``vibsynth serve`` (null output by default) with a private user preset folder and config.

    The OSC tests' starter (:func:`tests.e2e.test_osc_e2e.start_serve`) with the studio on a free
    port, a token of its own, and ready once the ``studio:`` line is printed and OSC answers.
    ``rate`` sets ``audio.rate``; ``extra_config`` (YAML) adds sections other than ``audio``,
    ``presets`` and ``studio``.
    """
    from tests.e2e.test_osc_e2e import _socket_ready
    from tests.e2e.test_osc_e2e import start_serve as start_osc_serve

    folder.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(24)
    user_dir = folder / "presets"
    extra = (
        f"audio:\n  channels: {channels}\n"
        + ("" if rate is None else f"  rate: {rate}\n")
        + f"presets:\n  user_dir: {json.dumps(str(user_dir))}\n  watch: true\n"
        + "studio:\n  port: 0\n"
        + extra_config
    )
    env = dict(
        os.environ,
        XDG_CONFIG_HOME=str(folder / "xdg-config"),
        XDG_DATA_HOME=str(folder / "xdg-data"),
        VIBSYNTH_HOST_API="JACK",
        JACK_NO_AUDIO_RESERVATION="1",
        VIBSYNTH_STUDIO_TOKEN=token,
    )
    log_path = folder / "serve.log"

    def studio_line() -> str | None:
        found = re.search(r"^studio: (http://\S+)$", log_path.read_text(), re.M) if log_path.exists() else None
        return found.group(1) if found else None

    proc, port = start_osc_serve(
        folder, output=output, extra_config=extra, env=env, ready=lambda p: bool(studio_line()) and _socket_ready(p)
    )
    url = studio_line()
    assert url is not None and url.endswith(f"?token={token}")
    return Served(proc, port, url, token, log_path, user_dir)


def require_browser() -> None:
    """Skip the test when the browser is missing (fail under ``VIBSYNTH_E2E_REQUIRED=1``)."""
    import pytest

    from tests.e2e.jackutil import e2e_required

    ok, reason = browser_available()
    if not ok:
        if e2e_required():
            pytest.fail(reason)
        pytest.skip(reason)


def chromium_or_skip(width: int = 1400, height: int = 1250) -> Any:
    """:func:`chromium` once :func:`require_browser` passes."""
    require_browser()
    return chromium(width, height)


def chromium(width: int = 1400, height: int = 1250) -> Any:
    """A headless Chromium (Selenium WebDriver) with its console log kept."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = CHROMIUM
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--disable-background-networking",
        f"--window-size={width},{height}",
    ):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def wait(driver: Any, condition: Callable[[Any], T], what: str, timeout: float = 20.0) -> T:
    """:func:`wait_for` on a condition of the browser: ``condition(driver)``."""
    return wait_for(lambda: condition(driver), timeout=timeout, what=what)


def by(testid: str) -> tuple[str, str]:
    """Selenium locator of a ``data-testid``."""
    from selenium.webdriver.common.by import By

    return By.CSS_SELECTOR, f'[data-testid="{testid}"]'


def by_testid(driver: Any, testid: str) -> Any:
    return driver.find_element(*by(testid))


def all_by_testid(driver: Any, testid: str) -> list[Any]:
    return driver.find_elements(*by(testid))


def visible(driver: Any, testid: str) -> Any:
    """The one displayed element with this ``data-testid`` (some exist in several views)."""
    shown = [e for e in all_by_testid(driver, testid) if e.is_displayed()]
    assert len(shown) == 1, f"{len(shown)} visible elements with data-testid={testid}"
    return shown[0]


def open_studio(driver: Any, served: Served) -> None:
    """Load the page with the token (it becomes a cookie) and wait until the page is live."""
    from selenium.webdriver.common.by import By

    driver.get(served.url)
    wait_for(lambda: driver.current_url.rstrip("/") == served.base, what="the redirect to the bare URL")
    wait_for(
        lambda: driver.find_element(By.ID, "connection").get_attribute("data-state") == "open",
        what="the WebSocket to open",
    )
    wait_for(lambda: by_testid(driver, "channel").get_attribute("value") == "1", what="the hello message")


def console_errors(driver: Any) -> list[str]:
    """Script errors of the page's console (refused requests the test provokes are network entries, not these)."""
    return [
        entry["message"]
        for entry in driver.get_log("browser")
        if entry["level"] == "SEVERE" and entry.get("source") != "network"
    ]
