"""One address type (host:port, parsed in one place) and one loopback rule for every
listener and every same-host shortcut."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from oricf.config import Schema, validate
from oricf.errors import ConfigError
from oricf.hosts import (
    Address,
    HostPort,
    ListenAddress,
    ListenTarget,
    UnixSocket,
    host_of,
    is_loopback,
    is_loopback_address,
    listen_address,
)


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


@pytest.mark.parametrize(("text", "host", "port"), [
    ("127.0.0.1:50051", "127.0.0.1", 50051), ("edge.local:1", "edge.local", 1),
    ("[::1]:8765", "::1", 8765), ("::1:8765", "::1", 8765),  # unbracketed: the last colon
    ("0.0.0.0:65535", "0.0.0.0", 65535), ("[fe80::1%eth0]:80", "fe80::1%eth0", 80)])
def test_an_address_is_parsed_into_host_and_port(text: str, host: str, port: int) -> None:
    assert Address.parse(text) == Address(host, port)


@pytest.mark.parametrize("text", ["127.0.0.1:50051", "edge.local:1", "[::1]:8765",
                                  "[fe80::1%eth0]:80"])
def test_an_address_reads_back_as_it_was_written(text: str) -> None:
    assert str(Address.parse(text)) == text
    assert str(Address.parse("::1:8765")) == "[::1]:8765"  # IPv6 in brackets, always


@pytest.mark.parametrize("text", ["localhost", "127.0.0.1:", ":50051", "[]:1", "host:port",
                                  "host:-1", "host:65536", "host:1e3", "host:５"])
def test_what_is_not_host_and_port_is_refused_naming_it(text: str) -> None:
    with pytest.raises(ValueError, match=rf"'{re.escape(text)}' is not host:port with a "
                                         rf"port 1-65535"):
        Address.parse(text)


def test_port_0_only_where_a_listener_may_pick_a_free_port() -> None:
    with pytest.raises(ValueError, match="port 1-65535"):
        Address.parse("127.0.0.1:0")
    assert Address.parse("127.0.0.1:0", any_port=True).port == 0
    with pytest.raises(ValueError, match="'x:70000' is not host:port with a port 0-65535"):
        Address.parse("x:70000", any_port=True)


def test_an_address_knows_loopback_and_where_a_local_client_reaches_it() -> None:
    assert Address.parse("[::1]:1").is_loopback and Address.parse("localhost:1").is_loopback
    assert not Address.parse("0.0.0.0:1").is_loopback
    assert Address.parse("0.0.0.0:7").reached_here() == Address("127.0.0.1", 7)
    assert Address.parse("[::]:7").reached_here() == Address("127.0.0.1", 7)
    assert Address.parse("10.0.0.7:7").reached_here() == Address("10.0.0.7", 7)


class _Schema(Schema):
    server: HostPort
    listen: ListenAddress
    control: ListenTarget


def test_schemas_validate_an_address_once_and_write_it_back_as_text() -> None:
    config = _Schema.model_validate({"server": "[::1]:50051", "listen": "127.0.0.1:0",
                                     "control": "unix:/run/oricf/control.sock"})
    assert config.server == Address("::1", 50051) and config.listen.port == 0
    assert config.control == UnixSocket(Path("/run/oricf/control.sock"))
    assert config.model_dump() == {"server": "[::1]:50051", "listen": "127.0.0.1:0",
                                   "control": "unix:/run/oricf/control.sock"}
    with pytest.raises(ConfigError, match=r"x\.yaml: server: '127\.0\.0\.1:0' is not host:port "
                                          r"with a port 1-65535"):
        validate({"server": "127.0.0.1:0", "listen": "a:1", "control": "a:1"}, _Schema,
                 "x.yaml")
    with pytest.raises(ConfigError, match=r"listen: 'unix:/x' is not host:port"):
        validate({"server": "a:1", "listen": "unix:/x", "control": "a:1"}, _Schema, "x.yaml")
    with pytest.raises(ConfigError, match=r"control: unix: needs a path"):
        validate({"server": "a:1", "listen": "a:1", "control": "unix:"}, _Schema, "x.yaml")


def test_a_bare_port_a_listener_binds_is_loopback() -> None:
    for bare in ("8080", ":8080", 8080):
        assert listen_address(bare) == Address("127.0.0.1", 8080)
    assert listen_address("0") == Address("127.0.0.1", 0)
    assert listen_address("[::1]:8080") == Address("::1", 8080)
    assert listen_address("0.0.0.0:8080") == Address("0.0.0.0", 8080)
    for bad in (":", "", "localhost", "99999", ":-1", "[::1]"):
        with pytest.raises(ValueError, match="host:port"):
            listen_address(bad)
