"""A second host for network tests: a network namespace joined to this one by a veth pair,
its link degradable (rate with tbf, random loss with iptables) and cuttable. Needs root,
`ip`, `tc` and `iptables` (scripts/setup.sh --dev installs iptables).

Traffic goes only to the namespace this creates (10.203.N.2); it is removed on exit.
Used by `oricf bench link` and tests/network.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from oricf.bench.entry import need_tools
from oricf.errors import ConfigError

PURPOSE = "an edge host in a network namespace (oricf.bench.netns)"


def _run(*argv: str) -> None:
    subprocess.run(argv, check=True, capture_output=True, timeout=30)


@dataclass
class EdgeHost:
    namespace: str
    local_link: str       # this side of the veth pair
    address: str          # the namespace's address, as seen from here

    def exec_argv(self, argv: list[str]) -> list[str]:
        """argv run inside the namespace."""
        return ["ip", "netns", "exec", self.namespace, *argv]

    def degrade(self, rate_mbit: float | None = None, loss: float = 0.0) -> None:
        """Caps what is sent to the host at rate_mbit (tbf) and drops `loss` of what it
        receives at random (iptables), replacing any earlier profile."""
        self.restore()
        if rate_mbit is not None:
            _run("tc", "qdisc", "add", "dev", self.local_link, "root", "tbf", "rate",
                 f"{rate_mbit}mbit", "burst", "32kbit", "latency", "400ms")
        if loss > 0:
            _run(*self.exec_argv(["iptables", "-A", "INPUT", "-m", "statistic", "--mode",
                                  "random", "--probability", str(loss), "-j", "DROP"]))

    def restore(self) -> None:
        subprocess.run(["tc", "qdisc", "del", "dev", self.local_link, "root"],
                       capture_output=True, timeout=30, check=False)
        _run(*self.exec_argv(["iptables", "-F", "INPUT"]))

    def cut(self) -> None:
        _run("ip", "link", "set", self.local_link, "down")

    def reconnect(self) -> None:
        _run("ip", "link", "set", self.local_link, "up")


@contextmanager
def edge_host() -> Iterator[EdgeHost]:
    need_tools(("ip", "tc", "iptables"), "Debian: iproute2 iptables; scripts/setup.sh --dev "
               "installs them", PURPOSE)
    if os.geteuid() != 0:
        raise ConfigError(f"{PURPOSE} needs root")
    tag = f"{os.getpid() % 100000}"
    namespace, local, remote = f"oricf-edge-{tag}", f"oe{tag}a", f"oe{tag}b"
    subnet = f"10.203.{os.getpid() % 250}"
    _run("ip", "netns", "add", namespace)
    try:
        _run("ip", "link", "add", local, "type", "veth", "peer", "name", remote)
        _run("ip", "link", "set", remote, "netns", namespace)
        _run("ip", "addr", "add", f"{subnet}.1/30", "dev", local)
        _run("ip", "link", "set", local, "up")
        inside = ["ip", "netns", "exec", namespace]
        _run(*inside, "ip", "addr", "add", f"{subnet}.2/30", "dev", remote)
        _run(*inside, "ip", "link", "set", remote, "up")
        _run(*inside, "ip", "link", "set", "lo", "up")
        yield EdgeHost(namespace, local, f"{subnet}.2")
    finally:
        subprocess.run(["ip", "link", "del", local], capture_output=True, timeout=30,
                       check=False)
        subprocess.run(["ip", "netns", "del", namespace], capture_output=True, timeout=30,
                       check=False)
