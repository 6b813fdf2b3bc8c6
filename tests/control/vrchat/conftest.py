"""Fixtures of the VRChat tests: the OSC tests' 4-channel controller (fake engine), handler and peer."""

from __future__ import annotations

from tests.control.osc import conftest as osc_fixtures

ctl = osc_fixtures.ctl
handler = osc_fixtures.handler
peer = osc_fixtures.peer
