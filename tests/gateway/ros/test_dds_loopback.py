"""ROS traffic stays on this machine: with ORICF's Fast DDS profile every DDS socket of a
process is bound to 127.0.0.1, and discovery still finds every participant on the host.

Each test starts a mesh of real rclpy processes on a ROS domain of its own, every one
publishing to and subscribing from all the others, as many as a robot's stack runs; each
reports the members it heard and the sockets it held (read from /proc, as `ss -tuanp` does).
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from oricf.gateway.ros.dds import dds_profile

REPOSITORY = Path(__file__).resolve().parents[3]
DISCOVERY_TIMEOUT_S = 120.0  # 16 processes starting rclpy on two shared cores


@dataclass
class Member:
    index: int
    kind: str  # oricf: set up as ORICF's processes are; plain: as a node ORICF did not write
    process: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)
    heard: set[int] = field(default_factory=set)  # as it reports them, then its last report
    reader: threading.Thread | None = None
    report: dict[str, Any] | None = None

    def read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))
            if line.startswith("heard "):
                self.heard = set(json.loads(line.split(" ", 1)[1]))

    @property
    def sockets(self) -> list[str]:
        assert self.report is not None
        return list(self.report["sockets"])

    def off_loopback(self) -> list[str]:
        """The sockets bound to an address other hosts can send to."""
        assert self.report is not None
        return list(self.report["off_loopback"])


def environment(domain: int, extra: dict[str, str]) -> dict[str, str]:
    """This mesh's domain; no Fast DDS setting of the test run's own, so an `oricf` member
    picks the profile itself, as `oricf gateway` and `oricf demo` do."""
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("FASTRTPS_", "FASTDDS_", "RMW_FASTRTPS_", "ROS_"))}
    return {**env, "ROS_DOMAIN_ID": str(domain), **extra}


def start(index: int, total: int, kind: str, env: dict[str, str]) -> Member:
    process = subprocess.Popen(
        [sys.executable, "-m", "tests.gateway.ros.mesh_member", str(index), str(total), kind],
        env=env, cwd=REPOSITORY, text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT)
    member = Member(index, kind, process)
    member.reader = threading.Thread(target=member.read, daemon=True)
    member.reader.start()
    return member


@contextmanager
def mesh(kinds: list[tuple[str, dict[str, str]]], domain: int,
         meeting: str | None = None) -> Iterator[list[Member]]:
    """Starts one member per (kind, environment), waits until each heard the others it
    should (see missing; or the timeout), then stops them all and collects their reports."""
    members: list[Member] = []
    try:
        for index, (kind, extra) in enumerate(kinds):
            members.append(start(index, len(kinds), kind, environment(domain, extra)))
        deadline = time.monotonic() + DISCOVERY_TIMEOUT_S
        while missing(members, meeting) and time.monotonic() < deadline:
            time.sleep(0.2)
        for member in members:
            stop(member)
        yield members
    finally:
        for member in members:
            if member.process.poll() is None:
                member.process.kill()
                member.process.wait(timeout=30)


def stop(member: Member) -> None:
    """Closes the member's input (it stops) and reads its report."""
    assert member.process.stdin is not None
    member.process.stdin.close()
    member.process.wait(timeout=60)
    assert member.reader is not None
    member.reader.join(timeout=10)  # it reads to the end of the output
    output = "\n".join(member.lines)
    reports = [line for line in member.lines if line.startswith("{")]
    assert member.process.returncode == 0 and reports, f"member {member.index}:\n{output}"
    member.report = json.loads(reports[-1])
    member.heard = set(member.report["heard"])


def missing(members: list[Member], kind: str | None = None) -> dict[int, list[int]]:
    """Member -> the others it never heard from (only those of this kind, if given, and
    every one for members of this kind)."""
    result = {}
    for member in members:
        expected = {m.index for m in members if kind in (None, member.kind, m.kind)}
        unheard = sorted(expected - {member.index} - member.heard)
        if unheard:
            result[member.index] = unheard
    return result


@pytest.mark.long
def test_sixteen_processes_meet_with_every_dds_socket_on_loopback() -> None:
    """ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST as users set it: without the profile's
    loopback settings, or with rmw_fastrtps's own LOCALHOST transports added to them, each
    process holds UDP and TCP sockets on 0.0.0.0 and on the machine's addresses. The default
    profile has no TCP transport (the TCP profile's sockets: the next test)."""
    kinds = [("oricf", {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})] * 16
    with mesh(kinds, domain=random.randint(1, 100)) as members:
        assert missing(members) == {}
        for member in members:
            assert any(s.startswith("udp 127.0.0.1:") for s in member.sockets), member.sockets
            assert not any(s.startswith("tcp") for s in member.sockets), member.sockets
            assert member.off_loopback() == [], f"member {member.index}: {member.sockets}"


@pytest.mark.long
@pytest.mark.parametrize("tcp", [False, True], ids=["default profile", "tcp profile"])
def test_nodes_without_the_profile_meet_the_nodes_with_it(tcp: bool) -> None:
    """Camera drivers and other nodes ORICF did not write: Fast DDS's defaults (multicast
    discovery), ROS's LOCALHOST range, and, meeting ORICF's TCP profile, Fast DDS's
    LARGE_DATA transports (multicast discovery, then TCP and shared memory only). Multicast
    reaches every test run on this machine, so the mesh takes a domain outside the range the
    other tests draw from. (LARGE_DATA nodes and nodes without TCP never meet each other:
    Fast DDS's own limit, tests/gateway/ros/test_foreign_camera.py.)"""
    plain = [{"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
             {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}]
    oricf = {}
    if tcp:
        plain.append({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FASTDDS_BUILTIN_TRANSPORTS":
                      "LARGE_DATA?max_msg_size=1MB&sockets_size=1MB"})
        oricf = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile(tcp=True))}
    kinds = [("oricf", oricf)] * 6 + [("plain", extra) for extra in plain for _ in range(2)]
    with mesh(kinds, domain=random.randint(101, 200), meeting="oricf") as members:
        assert missing(members, "oricf") == {}
        for member in members:
            if member.kind == "oricf":
                assert member.off_loopback() == [], f"member {member.index}: {member.sockets}"
                assert any(s.startswith("tcp 127.0.0.1:") for s in member.sockets) == tcp, \
                    member.sockets
