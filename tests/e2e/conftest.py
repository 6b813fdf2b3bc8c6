"""End-to-end tests: real PortAudio/JACK, OSC sockets, MIDI ports.

They are marked ``e2e`` and skip when the needed server is missing, unless
``VIBSYNTH_E2E_REQUIRED=1`` (CI), where they fail. Run them under a private JACK
server: ``scripts/with_jack.sh -- python -m pytest tests/e2e -q``.
"""

from __future__ import annotations

import pytest

from tests.e2e.jackutil import require_jack


@pytest.fixture
def jack_server() -> None:
    """Skip (or fail under VIBSYNTH_E2E_REQUIRED=1) when no JACK server is reachable."""
    require_jack()
