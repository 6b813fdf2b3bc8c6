"""The ``osc.allow`` setting: which sender addresses the OSC server accepts (IP networks, ``localhost``).

Parsed once at start-up from the config; the compiled receive loop checks the networks per datagram.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable, Iterator

from vibsynth.errors import ConfigError

Network = ipaddress.IPv4Network | ipaddress.IPv6Network

LOCALHOST_NETWORKS = (ipaddress.ip_network("127.0.0.0/8"), ipaddress.ip_network("::1/128"))
"""What the ``osc.allow`` entry ``localhost`` stands for."""


def _entry_networks(entry: object) -> tuple[Network, ...] | str:
    """The networks of one ``osc.allow`` entry, or why it is not valid (a phrase)."""
    if not isinstance(entry, str):
        return "must be a quoted string, e.g. '192.168.1.0/24'"
    if entry.strip().lower() == "localhost":
        return LOCALHOST_NETWORKS
    try:
        net = ipaddress.ip_network(entry, strict=False)
    except ValueError:
        return (
            "is not an IP address or network (e.g. 192.168.1.0/24, 10.0.0.0/8, ::1) or 'localhost'; "
            "host names are not accepted"
        )
    mapped = net.network_address.ipv4_mapped if isinstance(net, ipaddress.IPv6Network) else None
    if mapped is not None and net.prefixlen >= 96:  # ::ffff:10.0.0.0/104 is 10.0.0.0/8
        return (ipaddress.ip_network(f"{mapped}/{net.prefixlen - 96}"),)
    return (net,)


def parse_allow_entry(entry: object) -> tuple[Network, ...]:
    """The networks of one ``osc.allow`` entry.

    An entry is an IP address (``192.168.1.20``, ``::1``), a network in CIDR notation
    (``192.168.0.0/16``, ``10.0.0.0/8``, ``::1/128``; host bits are ignored, so
    ``192.168.1.7/24`` is ``192.168.1.0/24``) or the word ``localhost`` (127.0.0.0/8 and
    ::1). Host names are not accepted: the list is checked for every packet and must
    not depend on a name server.

    Raises
    ------
    ConfigError
        For anything else (the message says what is allowed).
    """
    found = _entry_networks(entry)
    if isinstance(found, str):
        raise ConfigError(f"{entry!r} {found}")
    return found


class AllowList:
    """Client networks allowed to talk to the server; ``ip in allow_list`` tests a peer address.

    Iterating yields the :mod:`ipaddress` networks. Membership answers are cached
    (bounded), since the check runs for every packet. An IPv4 client seen by an IPv6
    socket (``::ffff:192.168.1.20``) is checked as its IPv4 address.

    Parameters
    ----------
    networks : iterable of IPv4Network or IPv6Network
    """

    _CACHE_MAX = 4096

    def __init__(self, networks: Iterable[Network]) -> None:
        self.networks = tuple(networks)
        self._cache: dict[str, bool] = {}

    def __iter__(self) -> Iterator[Network]:
        return iter(self.networks)

    def __len__(self) -> int:
        return len(self.networks)

    def __repr__(self) -> str:
        return f"AllowList({', '.join(str(n) for n in self.networks)})"

    def __contains__(self, host: object) -> bool:
        hit = self._cache.get(str(host))
        if hit is None:
            hit = self._check(str(host))
            if len(self._cache) < self._CACHE_MAX:
                self._cache[str(host)] = hit
        return hit

    def _check(self, host: str) -> bool:
        try:
            ip = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return any(ip in net for net in self.networks if net.version == ip.version)


def parse_allow_list(entries: object) -> AllowList | None:
    """Parse ``osc.allow``: a list of entries (see :func:`parse_allow_entry`); None = allow all.

    This one function decides for both the config validator and the server, so a value
    the config accepts always starts the server.

    Raises
    ------
    ConfigError
        If ``entries`` is not a list or an entry is invalid (``item {i} (...) is not ...``).
    """
    if entries is None:
        return None
    if not isinstance(entries, (list, tuple)):
        raise ConfigError("must be a list of IP addresses or networks, e.g. ['127.0.0.1', '192.168.1.0/24']")
    networks: list[Network] = []
    for i, entry in enumerate(entries):
        found = _entry_networks(entry)
        if isinstance(found, str):
            raise ConfigError(f"item {i} ({entry!r}) {found}")
        networks.extend(found)
    return AllowList(networks) if networks else None


def resolve_allow_list(entries: Iterable[str] | None) -> AllowList | None:
    """The server's allow-list from ``osc.allow`` (None = allow all); see :func:`parse_allow_list`.

    Raises
    ------
    ConfigError
        ``osc.allow: item 0 ('...') is not an IP address or network ...``.
    """
    try:
        return parse_allow_list(list(entries) if isinstance(entries, (set, frozenset)) else entries)
    except ConfigError as exc:
        raise ConfigError(f"osc.allow: {exc}") from None
