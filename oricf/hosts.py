"""Network addresses: the one `host:port` type (Address), parsed in one place for every
listener, client and config schema, and whether a host is this machine's loopback: one
answer for every listener that binds loopback unless secured, and every client that takes a
shortcut (shared memory, a local service) only when its peer is on this host.

Other target forms (a control API's `unix:PATH`, gRPC's `dns:///NAME:PORT` and
`ipv4:IP:PORT,...`) are not Addresses; the code that accepts them reads their prefix and
hands the host:port parts here.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import PlainSerializer, PlainValidator

LOOPBACK_NAMES = frozenset({"localhost", "ip6-localhost"})
# Hosts that bind every interface: a client on this machine reaches them on loopback.
WILDCARD_HOSTS = frozenset({"0.0.0.0", "::"})
UNIX = "unix:"


@dataclass(frozen=True)
class Address:
    """A host (a name, an IPv4 or an IPv6 address, kept without brackets) and a port."""

    host: str
    port: int

    @classmethod
    def parse(cls, value: str, *, any_port: bool = False) -> Address:
        """`host:port`, an IPv6 host in brackets (`[::1]:80`; without them the port is what
        follows the last colon). The port is 1-65535, or 0-65535 with `any_port` (a listener
        binding port 0 gets a free one). ValueError naming the value otherwise."""
        host, sep, port = value.rpartition(":")
        if host.startswith("[") and host.endswith("]"):
            host = host[1:-1]
        lowest = 0 if any_port else 1
        if (not sep or not host or not (port.isascii() and port.isdigit())
                or not lowest <= int(port) <= 65535):
            raise ValueError(f"'{value}' is not host:port with a port {lowest}-65535")
        return cls(host, int(port))

    def __str__(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"

    @property
    def is_loopback(self) -> bool:
        return is_loopback(self.host)

    def reached_here(self) -> Address:
        """Where a client on this machine reaches a server listening here: a wildcard host
        (every interface) on 127.0.0.1."""
        return Address("127.0.0.1", self.port) if self.host in WILDCARD_HOSTS else self


@dataclass(frozen=True)
class UnixSocket:
    """`unix:PATH`: a listener on this machine only, reached through the file system."""

    path: Path

    def __str__(self) -> str:
        return f"{UNIX}{self.path}"


def _address(value: Any, any_port: bool) -> Address:
    if isinstance(value, Address):
        return value
    if not isinstance(value, str):
        raise ValueError(f"'{value}' is not host:port")
    return Address.parse(value, any_port=any_port)


def _listen_or_socket(value: Any) -> Address | UnixSocket:
    if isinstance(value, UnixSocket):
        return value
    if isinstance(value, str) and value.startswith(UNIX):
        if not value[len(UNIX):]:
            raise ValueError("unix: needs a path")
        return UnixSocket(Path(value[len(UNIX):]))
    return _address(value, any_port=True)


# In a config schema: an address a server connects to (port 1-65535) ...
HostPort = Annotated[Address, PlainValidator(lambda v: _address(v, any_port=False)),
                     PlainSerializer(str, return_type=str)]
# ... one a listener binds (port 0: a free one) ...
ListenAddress = Annotated[Address, PlainValidator(lambda v: _address(v, any_port=True)),
                          PlainSerializer(str, return_type=str)]
# ... or that, or a Unix socket (`unix:PATH`).
ListenTarget = Annotated[Address | UnixSocket, PlainValidator(_listen_or_socket),
                         PlainSerializer(str, return_type=str)]


def host_of(target: str) -> str:
    """The host of `host:port` (a bracketed IPv6 host allowed); '' for what is not one."""
    try:
        return Address.parse(target, any_port=True).host
    except ValueError:
        return ""


def listen_address(value: str | int) -> Address:
    """What a listener binds: `host:port`, or a bare port (`8080`, `:8080`) on 127.0.0.1,
    loopback unless a host is named. Port 0 picks a free one. ValueError naming the value
    otherwise."""
    text = str(value)
    if text.removeprefix(":").isascii() and text.removeprefix(":").isdigit():
        text = f"127.0.0.1:{text.removeprefix(':')}"
    return Address.parse(text, any_port=True)


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or a loopback name. Any other host name may resolve anywhere."""
    host = host.strip("[]")
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def is_loopback_address(target: str) -> bool:
    """`host:port` on this machine's loopback (a target naming replicas never is)."""
    return is_loopback(host_of(target))
