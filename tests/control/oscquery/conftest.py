"""Fixtures of the OSCQuery tests: a 4-channel controller and handler (fake engine), its tree and server."""

from __future__ import annotations

import pytest

from tests.control.osc import conftest as osc_fixtures
from tests.control.osc.fakes import PRESETS
from vibsynth.control.oscquery.methods import method_nodes, reads
from vibsynth.control.oscquery.server import OscQueryServer
from vibsynth.control.oscquery.tree import Tree


class Names:
    """A library's names that a test can change (a preset file added on disk)."""

    def __init__(self, names: list[str]) -> None:
        self.list = list(names)

    def names(self) -> list[str]:
        return list(self.list)


#: The OSC tests' 4-channel controller (fake engine) and its handler with every table registered.
ctl = osc_fixtures.ctl
handler = osc_fixtures.handler


@pytest.fixture
def presets():
    return Names(sorted(PRESETS))


@pytest.fixture
def tree(handler, ctl, presets):
    return Tree(method_nodes(handler, presets.names, lambda: ["impact", "tick"]), reads(ctl), root_description="test")


@pytest.fixture
def server(tree, handler, ctl):
    srv = OscQueryServer(tree, handler, ctl, host="127.0.0.1", port=0, osc_port=9570, name="vibsynth test")
    srv.start()
    yield srv
    srv.stop()
