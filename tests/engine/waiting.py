"""Waiting in tests without timed assertions: conditions with generous deadlines."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")

#: Generous: only a hang (a bug) gets near it, a loaded machine does not.
DEADLINE_S = 20.0


def wait_until(condition: Callable[[], Any], what: str, timeout_s: float = DEADLINE_S) -> None:
    """Poll ``condition`` until it is true; fail naming ``what`` if the deadline passes first."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not true after {timeout_s:g} s")
        time.sleep(0.005)


def returns(fn: Callable[[], T], what: str, timeout_s: float = DEADLINE_S) -> T:
    """Call ``fn`` in a helper thread; its result (or exception) if it returns, a failure if it hangs.

    For calls that must not block forever (abandoned driver calls): the test fails instead of hanging.
    """
    result: list[Any] = []
    error: list[BaseException] = []

    def run() -> None:
        try:
            result.append(fn())
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            error.append(exc)

    thread = threading.Thread(target=run, name=f"test: {what}", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        raise AssertionError(f"{what} did not return within {timeout_s:g} s (hung)")
    if error:
        raise error[0]
    return result[0]
