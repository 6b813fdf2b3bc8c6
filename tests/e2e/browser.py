"""Browser end-to-end helpers: ``vibsynth serve`` with its studio in a subprocess, headless Chromium.

Debian's ``chromium`` and ``chromium-driver`` (installed by ``scripts/setup.sh --test``) through
Selenium. Without them the tests skip, or fail when ``VIBSYNTH_E2E_REQUIRED=1``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.e2e.jackutil import e2e_required

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 120.0
WAIT_S = 20.0


def chromium_or_skip(width: int = 1400, height: int = 1000) -> Any:
    """A headless Chromium driven by Selenium (the caller quits it)."""
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
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", f"--window-size={width},{height}"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(driver_path), options=options)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Studio:
    """A running ``vibsynth serve`` with its studio."""

    base: str
    token: str
    state: dict[str, Any]
    log: Path

    @property
    def url(self) -> str:
        return f"{self.base}/?token={self.token}"


@contextlib.contextmanager
def serve_studio(tmp_path: Path, config: str, *, token: str, channels: int = 1) -> Iterator[Studio]:
    """Run ``vibsynth serve --output null`` with ``config`` (YAML text) until the block ends.

    The user's folders (config, data, cache) are inside ``tmp_path``.
    """
    studio_port, osc_port = free_port(), free_port(socket.SOCK_DGRAM)
    config_path = tmp_path / "vibsynth.yaml"
    config_path.write_text(config)
    env = dict(
        os.environ,
        PYTHONPATH=str(ROOT),
        XDG_CONFIG_HOME=str(tmp_path / "cfg"),
        XDG_DATA_HOME=str(tmp_path / "data"),
        XDG_CACHE_HOME=str(tmp_path / "cache"),
    )
    cmd = [
        sys.executable, "-m", "vibsynth", "serve", "--config", str(config_path), "--output", "null", "--no-midi",
        "--osc-port", str(osc_port), "--studio-port", str(studio_port), "--studio-token", token,
        "--channels", str(channels),
    ]  # fmt: skip
    log_path = tmp_path / "serve.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{studio_port}"
    deadline = time.monotonic() + START_TIMEOUT_S
    try:
        while True:
            if proc.poll() is not None:
                raise AssertionError(f"serve exited ({proc.returncode}):\n{log_path.read_text()}")
            try:
                request = urllib.request.Request(f"{base}/api/state", headers={"Authorization": f"Bearer {token}"})
                with urllib.request.urlopen(request, timeout=1) as response:
                    state = json.load(response)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError("the studio did not answer in time:\n" + log_path.read_text()) from None
                time.sleep(0.2)
        yield Studio(base, token, state, log_path)
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def wait(browser: Any, condition: Callable[[Any], Any], what: str, timeout: float = WAIT_S) -> Any:
    """Wait until ``condition(browser)`` is truthy; its value."""
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(browser, timeout).until(lambda b: condition(b), message=f"waiting for {what}")


def by(testid: str) -> tuple[str, str]:
    """Selenium locator of a ``data-testid``."""
    from selenium.webdriver.common.by import By

    return By.CSS_SELECTOR, f"[data-testid={testid}]"


def visible(browser: Any, testid: str) -> Any:
    """The one displayed element with this ``data-testid`` (some exist in several views)."""
    shown = [e for e in browser.find_elements(*by(testid)) if e.is_displayed()]
    assert len(shown) == 1, f"{len(shown)} visible elements with data-testid={testid}"
    return shown[0]
