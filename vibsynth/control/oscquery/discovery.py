"""mDNS (zeroconf): advertise ``_oscjson._tcp`` and ``_osc._udp``; find the OSCQuery services on the network.

:class:`Advertiser` registers both services on a background thread (mDNS probing takes about
a second: ``serve`` does not wait for it). A name another host already uses is one warning
and a count (``discovery.name_conflict``); the service is then advertised under the next free
name (``NAME (2)``) and nothing else changes. :func:`discover` browses for a while and reads
each service's ``HOST_INFO`` (name, OSC address) over HTTP.
"""

from __future__ import annotations

import json
import logging
import socket
import threading
import time
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from vibsynth.errors import VibsynthError

__all__ = ["OSCJSON_TYPE", "OSC_TYPE", "Advertiser", "Found", "discover", "default_name"]

log = logging.getLogger(__name__)

OSCJSON_TYPE = "_oscjson._tcp.local."
OSC_TYPE = "_osc._udp.local."
#: How long the advertiser asks whether its name is taken before registering (ms).
CHECK_MS = 1000
#: Largest HOST_INFO answer read from a found service (bytes).
HOST_INFO_CAP = 65536


def default_name() -> str:
    """``vibsynth on HOSTNAME`` (an mDNS label: at most 63 bytes, no dots)."""
    host = socket.gethostname().split(".")[0] or "localhost"
    return f"vibsynth on {host}"[:63]


def _wildcard(address: str) -> bool:
    return address in ("0.0.0.0", "", "::")


class Advertiser:
    """Advertise the OSC server and its OSCQuery server over mDNS.

    Parameters
    ----------
    name : str
        The instance name tools show.
    osc_port, oscquery_port : int
    addresses : sequence of str
        IP addresses to advertise (and to send mDNS on); a wildcard (``0.0.0.0``) = every interface.
    count : callable, optional
        ``count(kind)``: counts a problem (the controller's error counters).
    """

    name_ = "discovery"

    def __init__(
        self,
        name: str,
        osc_port: int,
        oscquery_port: int,
        addresses: Sequence[str],
        *,
        count: Any = None,
    ) -> None:
        self.requested_name = name
        self.name = name
        self.osc_port = int(osc_port)
        self.oscquery_port = int(oscquery_port)
        self.addresses = list(addresses)
        self.count = count or (lambda kind: None)
        self.conflicts = 0
        self.failed: str | None = None
        self.registered = threading.Event()
        self._zc: Any = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def describe(self) -> str:
        where = "every interface" if any(_wildcard(a) for a in self.addresses) else ", ".join(self.addresses)
        return f"mDNS: advertising {self.requested_name!r} (_oscjson._tcp, _osc._udp) on {where}"

    def start(self) -> None:
        """Register both services on a background thread (returns at once)."""
        self._thread = threading.Thread(target=self._register, name="vibsynth-mdns", daemon=True)
        self._thread.start()

    def wait(self, timeout_s: float = 10.0) -> bool:
        """Wait until both services are registered (or registering failed); True when registered."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return self.registered.is_set()

    def _infos(self, name: str) -> list[Any]:
        from zeroconf import ServiceInfo

        host = "".join(c if c.isalnum() else "-" for c in name).strip("-")[:50] or "vibsynth"
        explicit = [a for a in self.addresses if not _wildcard(a)]
        if not explicit:
            import ifaddr

            every = [str(ip.ip) for adapter in ifaddr.get_adapters() for ip in adapter.ips if isinstance(ip.ip, str)]
            explicit = [a for a in every if not a.startswith("127.")] or every
        kwargs: dict[str, Any] = {"parsed_addresses": explicit}
        return [
            ServiceInfo(
                OSCJSON_TYPE,
                f"{name}.{OSCJSON_TYPE}",
                port=self.oscquery_port,
                properties={"txtvers": "1"},
                server=f"{host}.local.",
                **kwargs,
            ),
            ServiceInfo(
                OSC_TYPE,
                f"{name}.{OSC_TYPE}",
                port=self.osc_port,
                properties={"txtvers": "1"},
                server=f"{host}.local.",
                **kwargs,
            ),
        ]

    def _register(self) -> None:
        try:
            from zeroconf import DNSQuestionType, InterfaceChoice, NonUniqueNameException, Zeroconf

            explicit = [a for a in self.addresses if not _wildcard(a)]
            zc = Zeroconf(interfaces=explicit if explicit else InterfaceChoice.All)
            with self._lock:
                self._zc = zc
            # Ask first, with a multicast question: probing alone can miss the owner's answer
            # (a unicast reply to port 5353 reaches one of the sockets bound there, maybe not ours).
            taken = zc.get_service_info(
                OSCJSON_TYPE, f"{self.name}.{OSCJSON_TYPE}", timeout=CHECK_MS, question_type=DNSQuestionType.QM
            )
            try:
                if taken is not None:
                    raise NonUniqueNameException
                for info in self._infos(self.name):
                    zc.register_service(info)
            except NonUniqueNameException:
                self._rename(zc)
            self.registered.set()
            log.info("mDNS: advertising %r", self.name)
        except Exception as exc:  # noqa: BLE001 - no multicast, no interface: one line, OSC keeps working
            self.failed = str(exc) or type(exc).__name__
            self.count("discovery.advertise")
            log.warning("mDNS: cannot advertise %r (%s); OSCQuery still answers at its address", self.name, self.failed)

    def _rename(self, zc: Any) -> None:
        """The name is taken: count it once, say it once, advertise under the next free name (``NAME-2``)."""
        self.conflicts += 1
        self.count("discovery.name_conflict")
        zc.unregister_all_services()
        for suffix in range(2, 100):
            name = f"{self.requested_name}-{suffix}"
            if zc.get_service_info(OSCJSON_TYPE, f"{name}.{OSCJSON_TYPE}", timeout=CHECK_MS // 4) is None:
                break
        oscjson = self._infos(name)[0]
        zc.register_service(oscjson, allow_name_change=True)
        self.name = oscjson.name[: -len(OSCJSON_TYPE) - 1]
        zc.register_service(self._infos(self.name)[1], allow_name_change=True)
        log.warning(
            "mDNS: the name %r is taken on the network; advertising as %r (set discovery.name)",
            self.requested_name,
            self.name,
        )

    def stop(self) -> None:
        """Withdraw the services (goodbye packets) and close (idempotent)."""
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        with self._lock:
            zc, self._zc = self._zc, None
        if zc is not None:
            try:
                zc.unregister_all_services()
            finally:
                zc.close()


@dataclass(frozen=True)
class Found:
    """An OSCQuery service found over mDNS (with its HOST_INFO when it answered)."""

    name: str
    oscquery_url: str
    osc_host: str | None
    osc_port: int | None
    osc_transport: str = "UDP"
    host_info: dict[str, Any] | None = None

    @property
    def osc(self) -> str:
        """``udp://HOST:PORT`` or ``?``."""
        if self.osc_host is None or self.osc_port is None:
            return "?"
        return f"{self.osc_transport.lower()}://{self.osc_host}:{self.osc_port}"


def host_info(url: str, timeout_s: float = 1.0) -> dict[str, Any]:
    """``GET url?HOST_INFO`` (bounded read); raises VibsynthError on any failure."""
    try:
        with urllib.request.urlopen(url.rstrip("/") + "/?HOST_INFO", timeout=timeout_s) as response:  # noqa: S310
            data = json.loads(response.read(HOST_INFO_CAP + 1)[:HOST_INFO_CAP])
    except (OSError, ValueError) as exc:
        raise VibsynthError(f"{url}: no HOST_INFO ({exc})") from None
    if not isinstance(data, dict):
        raise VibsynthError(f"{url}: HOST_INFO is not a JSON object")
    return data


def discover(timeout_s: float = 2.0, *, interfaces: Sequence[str] | None = None) -> list[Found]:
    """Browse ``_oscjson._tcp`` for ``timeout_s`` seconds; each service with its HOST_INFO, sorted by name.

    Parameters
    ----------
    timeout_s : float
        How long to listen for answers.
    interfaces : sequence of str, optional
        IP addresses to browse on (default: every interface).
    """
    from zeroconf import InterfaceChoice, ServiceBrowser, ServiceListener, Zeroconf

    names: set[str] = set()

    class Listener(ServiceListener):
        def add_service(self, zc: Zeroconf, type_: str, name: str) -> None:
            names.add(name)

        def update_service(self, zc: Zeroconf, type_: str, name: str) -> None:
            names.add(name)

        def remove_service(self, zc: Zeroconf, type_: str, name: str) -> None:
            names.discard(name)

    zc = Zeroconf(interfaces=list(interfaces) if interfaces else InterfaceChoice.All)
    try:
        browser = ServiceBrowser(zc, OSCJSON_TYPE, Listener())
        time.sleep(timeout_s)
        browser.cancel()
        found = []
        for name in sorted(names):
            info = zc.get_service_info(OSCJSON_TYPE, name, timeout=1000)
            if info is None or not info.parsed_addresses():
                continue
            address = info.parsed_addresses()[0]
            host = f"[{address}]" if ":" in address else address
            url = f"http://{host}:{info.port}/"
            short = name[: -len(OSCJSON_TYPE) - 1]
            try:
                hi = host_info(url)
            except VibsynthError:
                found.append(Found(short, url, None, None))
                continue
            port = hi.get("OSC_PORT")
            found.append(
                Found(
                    short,
                    url,
                    str(hi.get("OSC_IP") or address),
                    int(port) if isinstance(port, int) else info.port,
                    str(hi.get("OSC_TRANSPORT") or "UDP"),
                    hi,
                )
            )
        return found
    finally:
        zc.close()
