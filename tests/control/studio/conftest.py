"""Fixtures of the studio tests: a studio server on a free port around a fake engine."""

from __future__ import annotations

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.control.studio.panels import install_panels
from vibsynth.control.studio.server import StudioServer


@pytest.fixture
def controller():
    return make_controller(2)


@pytest.fixture
def studio(controller):
    server = StudioServer(controller, port=0)
    install_panels(server)
    server.start()
    yield server
    server.stop()
