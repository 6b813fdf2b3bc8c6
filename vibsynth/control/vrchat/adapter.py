"""The VRChat bridge for ``vibsynth serve``: built from ``vrchat:`` for the running OSC (and OSCQuery) server.

Not in :data:`vibsynth.control.ADAPTER_MODULES`: it is a namespace of the OSC server's handler,
so the service builds it after OSC and OSCQuery (:func:`create` gets both). It adds:

* the ``/avatar/`` namespace to the handler (avatar parameters on the OSC port);
* ``/avatar/change`` and the mapped parameters to the OSCQuery tree, so VRChat, which browses
  for OSCQuery services, sends us its avatar parameters;
* a second UDP socket on localhost ``vrchat.listen_port`` (9001, VRChat's output port for apps it
  does not find over OSCQuery), closed once VRChat is found over mDNS (it then sends to our OSC
  port: one copy of each message);
* VRChat's own OSC input (status ``vrchat.osc``): its HOST_INFO when found, else ``vrchat.host``
  and ``vrchat.send_port``;
* once VRChat is found, its current avatar parameter values, read from its OSCQuery tree
  (:mod:`~vibsynth.control.vrchat.values`), so a hand already resting on a Contact Receiver is
  felt at once; read again after each ``/avatar/change`` (status ``vrchat.primed``).
"""

from __future__ import annotations

import argparse
import logging
import threading
from typing import Any

from vibsynth.control.controller import Controller
from vibsynth.control.osc.transport import UdpTransport
from vibsynth.control.vrchat.bridge import ROOT, VrchatBridge
from vibsynth.control.vrchat.finder import VrchatAddress, pick
from vibsynth.control.vrchat.values import read_avatar
from vibsynth.errors import VibsynthError
from vibsynth.settings.models_config import VibsynthConfig

__all__ = ["VrchatService", "create"]

log = logging.getLogger(__name__)

#: How long one mDNS browse for VRChat lasts, and the pause between browses until it is found.
BROWSE_S = 3.0
BROWSE_EVERY_S = 30.0
#: After ``/avatar/change``, VRChat's tree is read again once the new avatar has loaded.
REREAD_AFTER_S = 1.0


class VrchatService:
    """The bridge with its fallback listener and the search for VRChat (a ControlServer)."""

    name = "vrchat"

    def __init__(self, bridge: VrchatBridge, handler: Any, settings: VibsynthConfig, *, find: bool) -> None:
        self.bridge = bridge
        self.handler = handler
        vrchat = settings.vrchat
        self.address = VrchatAddress(vrchat.host, vrchat.send_port, False)
        bridge.found = self.address.describe()
        self.listen_port = vrchat.listen_port
        self.listener: UdpTransport | None = None
        self.find = find
        self._stop = threading.Event()
        self._changed = threading.Event()
        self._finder: threading.Thread | None = None
        bridge.on_avatar_change = self._changed.set

    def start(self) -> None:
        self.bridge.start()
        if self.listen_port:
            listener = UdpTransport("127.0.0.1", self.listen_port, self.handler.handle_batch)
            try:
                listener.open()
                listener.start()
                self.listener = listener
            except OSError as exc:
                listener.stop()
                self.bridge.controller.count_error("vrchat.listen")
                log.warning("VRChat: cannot listen on 127.0.0.1:%d (%s); set vrchat.listen_port", self.listen_port, exc)
        if self.find:
            self._finder = threading.Thread(target=self._search, name="vibsynth-vrchat-mdns", daemon=True)
            self._finder.start()

    def _search(self) -> None:
        from vibsynth.control.oscquery.discovery import discover

        while not self._stop.is_set():
            try:
                found = pick(discover(BROWSE_S), self.address.host, self.address.port)
            except Exception as exc:  # noqa: BLE001 - no multicast here: the fallback stays
                log.info("VRChat: mDNS browse failed (%s)", exc)
                return
            if found.found:
                self.address = found
                self.bridge.found = found.describe()
                log.info("VRChat found: OSC input %s; it sends avatar parameters over OSCQuery", found.describe())
                self._close_listener()
                self._follow_values(found.oscquery_url)
                return
            self._stop.wait(BROWSE_EVERY_S)

    def _follow_values(self, url: str) -> None:
        """Prime the bridge from VRChat's tree now and after each avatar change, until stopped."""
        self._changed.clear()
        while not self._stop.is_set():
            try:
                found = read_avatar(url)
            except VibsynthError as exc:
                self.bridge.controller.count_error("vrchat.read")
                log.warning("VRChat: cannot read its avatar parameters: %s", exc)
            else:
                primed = self.bridge.prime(found.parameters, found.avatar)
                log.info("VRChat: %d mapped avatar parameter(s) read from its OSCQuery tree", primed)
            while not self._stop.is_set() and not self._changed.wait(0.5):
                pass
            self._changed.clear()
            self._stop.wait(REREAD_AFTER_S)

    def _close_listener(self) -> None:
        listener, self.listener = self.listener, None
        if listener is not None:
            listener.stop()

    def stop(self) -> None:
        self._stop.set()
        if self._finder is not None:
            self._finder.join(BROWSE_S + 2.0)
            self._finder = None
        self._close_listener()
        self.bridge.stop()

    def describe(self) -> str:
        text = self.bridge.describe()
        if self.listener is not None:
            text += f"; also on udp://127.0.0.1:{self.listener.port} (VRChat's output port)"
        return text


def create(
    settings: VibsynthConfig, args: argparse.Namespace | None, controller: Controller, osc_server: Any, oscquery: Any
) -> VrchatService | None:
    """Build (not start) the bridge for a running OSC server (and its OSCQuery service, or None); None when off."""
    if not settings.vrchat.enabled:
        return None
    if osc_server is None:
        log.warning("VRChat: vrchat.enabled needs the OSC server (avatar parameters arrive over OSC)")
        return None
    bridge = VrchatBridge(settings.vrchat, controller)
    osc_server.handler.register_namespace(ROOT, bridge)
    if oscquery is not None:
        oscquery.tree.register(bridge)
        oscquery.tree.refresh()
        bridge.on_value = oscquery.server.value_changed
    # VRChat finds only services advertised on a real interface: browse for it only then (never
    # multicast for a loopback-only server)
    find = oscquery is not None and getattr(oscquery, "advertiser", None) is not None
    return VrchatService(bridge, osc_server.handler, settings, find=find)
