"""Method tables registered into the OSC handler from outside (control/osc/methods.py, tables.py)."""

from __future__ import annotations

import pytest

from tests.control.osc.fakes import FakePeer, make_controller, send
from vibsynth.control.osc.handler import OscHandler
from vibsynth.control.osc.methods import arg_count, number
from vibsynth.control.osc.tables import register_tables
from vibsynth.errors import ClipError, ParameterError


class Recorder:
    """A table with one method and one ``get`` name that records what reaches it."""

    def __init__(self, method: str = "play", getter: str = "clip", fail: Exception | None = None) -> None:
        self.method, self.getter, self.fail = method, getter, fail
        self.calls: list[tuple] = []

    def methods(self):
        return {self.method: self.on_call}

    def getters(self):
        return {self.getter: self.on_get}

    def on_call(self, msg, channels, peer, at_frame) -> None:
        arg_count(msg, (1,), "a number")
        value = number(msg, 0, "value")
        if self.fail is not None:
            raise self.fail
        self.calls.append((msg.address, channels, value, at_frame))

    def on_get(self, peer, channels) -> None:
        self.calls.append(("get", channels))


def test_a_bare_handler_answers_unregistered_methods_with_an_error_and_changes_nothing():
    ctl = make_controller(2)
    handler, peer = OscHandler(ctl, sync_worker=None), FakePeer()
    before = ctl.state()
    for address in ("/vibsynth/ch/1/play", "/vibsynth/source/1/intensity"):
        send(handler, peer, address, 0.5)
    assert peer.errors() == [
        ("/vibsynth/ch/1/play", "play: not available on this server"),
        ("/vibsynth/source/1/intensity", "source/intensity: not available on this server"),
    ]
    assert ctl.error_counts == {"osc.unavailable": 2} and ctl.state() == before
    peer.clear()
    send(handler, peer, "/vibsynth/get", "clip")
    assert peer.errors()[0][1] == (
        "unknown setting 'clip'; known: intensity, balance, glide, mute, preset, texture, driver"
    )


def test_a_registered_table_gets_its_routes_its_get_name_and_its_errors_replied():
    ctl = make_controller(4)
    handler, peer, table = OscHandler(ctl, sync_worker=None), FakePeer(), Recorder()
    handler.register(table)
    send(handler, peer, "/vibsynth/ch/3/play", 0.25)
    send(handler, peer, "/vibsynth/play", 0.5)
    send(handler, peer, "/vibsynth/ch/2/get", "clip")
    assert table.calls == [
        ("/vibsynth/ch/3/play", (2,), 0.25, None),
        ("/vibsynth/play", None, 0.5, None),
        ("get", (1,)),
    ]
    assert peer.errors() == []
    send(handler, peer, "/vibsynth/play", "loud")  # the shared argument checks answer as the handler's own
    assert peer.errors() == [("/vibsynth/play", "play: value must be a number (OSC type i, f, d or h), got type 's'")]
    send(handler, peer, "/vibsynth/get", "nothing")
    assert peer.errors()[-1][1].endswith("known: intensity, balance, glide, mute, preset, texture, driver, clip")


def test_a_clip_error_from_a_table_is_replied_and_counted_as_osc_clip():
    ctl = make_controller(1)
    handler, peer = OscHandler(ctl, sync_worker=None), FakePeer()
    handler.register(Recorder(fail=ClipError("unknown clip 'impakt'; did you mean impact?")))
    send(handler, peer, "/vibsynth/play", 1.0)
    assert peer.errors() == [("/vibsynth/play", "unknown clip 'impakt'; did you mean impact?")]
    assert ctl.error_counts == {"osc.clip": 1}


@pytest.mark.parametrize(
    "table, taken",
    [
        (Recorder(method="intensity", getter="x"), "intensity"),  # the handler's own method
        (Recorder(method="y", getter="texture"), "texture"),  # a setting get answers itself
        (Recorder(method="play", getter="z"), "play"),  # registered by register_tables
        (Recorder(method="w", getter="clip"), "clip"),
    ],
)
def test_a_name_is_registered_once(table, taken):
    handler = register_tables(OscHandler(make_controller(1), sync_worker=None))
    with pytest.raises(ParameterError, match=f"OSC methods registered twice: {taken}$"):
        handler.register(table)


def test_the_registered_tables_serve_every_route_of_the_address_space():
    ctl = make_controller(3)
    handler, peer = register_tables(OscHandler(ctl, sync_worker=None)), FakePeer()
    for address in handler.space.addresses:
        if not address.endswith("/sync"):  # waits for the engine; its method is the handler's own
            send(handler, peer, address)
    unavailable = [e for e in peer.errors() if "not available on this server" in e[1]]
    assert unavailable == [] and len(peer.errors()) > 100  # every route reached a method (which refused no args)
