"""The IPv4 and IPv6 sockets a process holds, read from Linux's /proc as `ss -tuanp` does;
whether a peer has closed a connection."""

from __future__ import annotations

import ipaddress
import os
import socket
from dataclasses import dataclass
from pathlib import Path

TABLES = ("udp", "tcp", "udp6", "tcp6")
TCP_LISTEN = "0A"


@dataclass(frozen=True)
class Socket:
    table: str  # udp, tcp, udp6 or tcp6
    address: ipaddress.IPv4Address | ipaddress.IPv6Address
    port: int
    state: str  # /proc's hex state: 0A a listening TCP socket, 07 an unconnected UDP one

    @property
    def loopback(self) -> bool:
        """127.0.0.0/8, ::1, or 127.0.0.1 as an IPv6 socket holds it (::ffff:127.0.0.1)."""
        mapped = getattr(self.address, "ipv4_mapped", None)
        return (mapped or self.address).is_loopback

    def __str__(self) -> str:
        return f"{self.table} {self.address}:{self.port}"


def socket_inodes(pid: int) -> set[str]:
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:  # closed since the listing
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:["):-1])
    return inodes


def local_address(hex_address: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address:
    """/proc writes an address as 32-bit words in the machine's (little-endian) order."""
    words = [bytes.fromhex(hex_address[i:i + 8])[::-1] for i in range(0, len(hex_address), 8)]
    return ipaddress.ip_address(b"".join(words))


def inet_sockets(pid: int) -> list[Socket]:
    """Every UDP and TCP socket of the process (listening, bound or connected), with the
    local address it is bound to."""
    inodes = socket_inodes(pid)
    found = []
    for table in TABLES:
        lines = Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]
        for line in lines:
            fields = line.split()
            if fields[9] in inodes:
                address, port = fields[1].split(":")
                found.append(Socket(table, local_address(address), int(port, 16), fields[3]))
    return found


def peer_closed(sock: socket.socket) -> bool:
    """Whether the other end has closed this connection, looked at without waiting."""
    sock.setblocking(False)
    try:
        return sock.recv(1, socket.MSG_PEEK) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
    finally:
        sock.setblocking(True)
