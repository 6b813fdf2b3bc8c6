"""Fixtures of the studio tests: a studio server on a free port around a fake engine and a preset library."""

from __future__ import annotations

import pytest

from tests.control.osc.fakes import make_controller
from vibsynth.control.studio.panels import install_panels
from vibsynth.control.studio.server import StudioServer
from vibsynth.settings.library import PresetLibrary, shipped_presets_dir


@pytest.fixture
def controller():
    return make_controller(2)


@pytest.fixture
def user_dir(tmp_path):
    return tmp_path / "user-presets"


@pytest.fixture
def library(user_dir):
    return PresetLibrary(shipped_presets_dir(), user_dir)


@pytest.fixture
def studio(controller, library):
    controller.preset_resolver = library.get
    server = StudioServer(controller, port=0, library=library)
    install_panels(server)
    server.start()
    yield server
    server.stop()
