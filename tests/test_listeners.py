"""Every listener shares one schema (address, TLS, tokens) and one rule for listening beyond
this machine (oricf.tls.check_exposure): the same refusal, naming the same keys."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from oricf.config import load_config, validate
from oricf.errors import ConfigError
from oricf.gateway.agents.http import McpListener
from oricf.gateway.channels.server import ChannelConfig
from oricf.gateway.config import load_pipeline
from oricf.gateway.listeners import ControlConfig, LiveViewConfig
from oricf.hosts import Address
from oricf.metrics import MetricsConfig
from oricf.services.runtime.config import ServiceConfig
from oricf.tls import Exposure, Listener, ListenerConfig, check_exposure

# Every listener of ORICF that takes tokens; a new one belongs here.
SECURED = [LiveViewConfig, ControlConfig, ChannelConfig, McpListener]
BEYOND = ["0.0.0.0:7000", "[::]:7000", "10.0.0.5:0", "edge.local:7000"]


def _settings(tmp_path: Path, tls: bool, auth: bool) -> dict[str, Any]:
    return {**({"tls": {"cert": str(tmp_path / "c.pem"), "key": str(tmp_path / "k.pem")}}
               if tls else {}),
            **({"auth": {"file": str(tmp_path / "tokens")}} if auth else {})}


def _refusal(cls: type[Listener], listen: str) -> str:
    with pytest.raises(ValueError) as expected:
        check_exposure(Address.parse(listen, any_port=True), tls=False, tokens=False,
                       exposure=Exposure.SECURED, keys=cls.keys)
    return str(expected.value)


@pytest.mark.parametrize("cls", SECURED)
@pytest.mark.parametrize("listen", BEYOND)
@pytest.mark.parametrize(("tls", "auth"), [(False, False), (True, False), (False, True)])
def test_beyond_loopback_every_listener_needs_tls_and_tokens(
        cls: type[ListenerConfig], listen: str, tls: bool, auth: bool, tmp_path: Path) -> None:
    assert issubclass(cls, ListenerConfig)
    with pytest.raises(ConfigError) as refused:
        validate({"listen": listen, **_settings(tmp_path, tls, auth)}, cls, "x.yaml")
    assert str(refused.value) == f"x.yaml: (top level): {_refusal(cls, listen)}"


@pytest.mark.parametrize("cls", SECURED)
@pytest.mark.parametrize("listen", BEYOND)
def test_beyond_loopback_with_both_every_listener_is_accepted(
        cls: type[ListenerConfig], listen: str, tmp_path: Path) -> None:
    config = validate({"listen": listen, **_settings(tmp_path, True, True)}, cls, "x.yaml")
    assert config.listen == Address.parse(listen, any_port=True)


@pytest.mark.parametrize("cls", [LiveViewConfig, ChannelConfig, McpListener])
@pytest.mark.parametrize("listen", ["127.0.0.1:0", "[::1]:7000", "localhost:7000"])
def test_loopback_needs_neither(cls: type[ListenerConfig], listen: str) -> None:
    assert validate({"listen": listen}, cls, "x.yaml").listen.is_loopback


def test_the_control_api_needs_tokens_on_loopback_too_but_not_on_its_socket() -> None:
    with pytest.raises(ConfigError, match=r"x\.yaml: \(top level\): listen 127\.0\.0\.1:7100: "
                                          r"a TCP address needs auth \(bearer tokens\)"):
        validate({"listen": "127.0.0.1:7100"}, ControlConfig, "x.yaml")
    config = validate({"listen": "unix:/run/oricf/control.sock"}, ControlConfig, "x.yaml")
    assert config.socket_path == Path("/run/oricf/control.sock")


def test_metrics_are_open_to_any_address(tmp_path: Path) -> None:
    """Counts, no secrets: compose and Kubernetes scrape them across their networks."""
    assert issubclass(MetricsConfig, Listener) and MetricsConfig.exposure is Exposure.OPEN
    assert validate({"listen": "0.0.0.0:9101"}, MetricsConfig, "x.yaml").listen.port == 9101


def test_a_text_channel_beyond_loopback_without_tls_and_auth_is_refused_at_load(
        tmp_path: Path) -> None:
    pipeline = tmp_path / "pipeline.yaml"
    pipeline.write_text("channels:\n  questions: {listen: 0.0.0.0:7000}\n")
    with pytest.raises(ConfigError, match=r"pipeline\.yaml: channels\.questions: listen "
                                          r"0\.0\.0\.0:7000 is reachable from other machines: "
                                          r"it needs auth and tls; set both tls and auth, or "
                                          r"listen on 127\.0\.0\.1"):
        load_pipeline(pipeline)


def test_a_metrics_listener_in_a_service_config_loads(tmp_path: Path) -> None:
    config = tmp_path / "service.yaml"
    config.write_text("server: {metrics: {listen: '[::1]:0'}}\n")
    metrics = load_config(config, ServiceConfig).server.metrics
    assert metrics is not None and metrics.listen == Address("::1", 0)
