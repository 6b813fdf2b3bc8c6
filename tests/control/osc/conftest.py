"""Fixtures of the OSC handler tests: a 4-channel controller on a fake engine, its handler, a peer."""

from __future__ import annotations

import pytest

from tests.control.osc.fakes import FakePeer, make_controller
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.tables import register_tables


@pytest.fixture
def ctl():
    return make_controller(channels=4)


@pytest.fixture
def handler(ctl):
    return register_tables(OscHandler(ctl, sync_worker=None))


@pytest.fixture
def peer():
    return FakePeer()
