"""One loopback rule for every listener and every same-host shortcut."""

from __future__ import annotations

from oricf.hosts import host_of, is_loopback, is_loopback_address


def test_loopback_addresses_are_this_machine() -> None:
    assert is_loopback_address("127.0.0.1:50051") and is_loopback_address("[::1]:50051")
    assert is_loopback_address("localhost:50051") and is_loopback_address("127.0.0.2:1")


def test_other_hosts_and_names_are_not() -> None:
    assert not is_loopback_address("10.0.0.5:50051")
    assert not is_loopback_address("edge.local:50051")   # a name may resolve anywhere
    assert not is_loopback_address("dns:///detector:50051")
    assert not is_loopback_address("0.0.0.0:50051")      # every interface, not loopback


def test_hosts_with_and_without_brackets() -> None:
    assert host_of("[::1]:8765") == "::1" and host_of("edge:1") == "edge"
    assert is_loopback("::1") and is_loopback("[::1]") and is_loopback("ip6-localhost")
    assert not is_loopback("") and not is_loopback("::")
