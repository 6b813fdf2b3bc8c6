"""End-to-end tests: real PortAudio/JACK, OSC sockets, MIDI ports.

They are marked ``e2e`` and skip when the needed server is missing, unless
``VIBSYNTH_E2E_REQUIRED=1`` (CI), where they fail. Run them under a private JACK
server: ``scripts/with_jack.sh -- python -m pytest tests/e2e -q``.

Every test here is also marked ``serial`` (scripts/test.sh runs those one at a time, after the
unit tests: they measure real time against a quiet baseline, or share the JACK graph and find
serve's ports by name), unless its module says ``PARALLEL_SAFE = True``: a file whose serve
plays into the null output and that measures no time (the studio, lab and C# client pages),
which then runs on the unit tests' workers.
"""

from __future__ import annotations

import pytest

from tests.e2e.jackutil import require_jack


@pytest.fixture
def jack_server() -> None:
    """Skip (or fail under VIBSYNTH_E2E_REQUIRED=1) when no JACK server is reachable."""
    require_jack()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every e2e test ``serial`` unless its module declares ``PARALLEL_SAFE = True``."""
    for item in items:
        module = getattr(item, "module", None)
        if "tests/e2e/" in item.nodeid.replace("\\", "/") and not getattr(module, "PARALLEL_SAFE", False):
            item.add_marker(pytest.mark.serial)
