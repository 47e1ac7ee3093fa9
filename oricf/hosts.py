"""Which host an address names, and whether it is this machine's loopback: one answer for
every listener that binds loopback unless secured, and every client that takes a shortcut
(shared memory, a local service) only when its peer is on this host."""

from __future__ import annotations

import ipaddress

LOOPBACK_NAMES = frozenset({"localhost", "ip6-localhost"})


def host_of(address: str) -> str:
    """`host:port` (a bracketed IPv6 host allowed) -> host."""
    return address.rpartition(":")[0].strip("[]")


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or a loopback name. Any other host name may resolve anywhere."""
    host = host.strip("[]")
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def is_loopback_address(address: str) -> bool:
    """`host:port` on this machine's loopback."""
    return is_loopback(host_of(address))
