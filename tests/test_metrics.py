"""The /metrics endpoint itself: plain HTTP, HTTPS with client certificates from `oricf
certs`, a client that never finishes its handshake, bad addresses, the histogram buckets."""

from __future__ import annotations

import socket
import ssl
import urllib.error
from collections.abc import Iterator
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry, Counter

from oricf.config import validate
from oricf.errors import ConfigError
from oricf.metrics import LatencyHistogram, MetricsConfig, MetricsServer
from oricf.services.runtime.config import ServiceConfig
from tests.support.metrics import scrape


def registry_with_a_count() -> CollectorRegistry:
    registry = CollectorRegistry()
    Counter("test_things", "Things.", registry=registry).inc(3)
    return registry


@pytest.fixture()
def https(certs: Path) -> Iterator[MetricsServer]:
    config = MetricsConfig.model_validate({"listen": "127.0.0.1:0", "tls": {
        "cert": certs / "server.pem", "key": certs / "server.key",
        "client_ca": certs / "ca.pem"}})
    server = MetricsServer(config, registry_with_a_count())
    yield server
    server.close()


def client_context(certs: Path, with_cert: bool = True) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    if with_cert:
        context.load_cert_chain(certs / "client.pem", certs / "client.key")
    return context


def test_plain_http_on_a_free_port() -> None:
    server = MetricsServer(MetricsConfig(listen="127.0.0.1:0"), registry_with_a_count())
    try:
        assert server.url == f"http://127.0.0.1:{server.port}/metrics"
        assert scrape(server.url).value("test_things_total") == 3
    finally:
        server.close()


def test_https_with_a_client_certificate(https: MetricsServer, certs: Path) -> None:
    assert https.url.startswith("https://")
    assert scrape(https.url, client_context(certs)).value("test_things_total") == 3


def test_https_refuses_a_client_without_a_certificate(https: MetricsServer,
                                                       certs: Path) -> None:
    with pytest.raises((ssl.SSLError, urllib.error.URLError, ConnectionError)):
        scrape(https.url, client_context(certs, with_cert=False))
    with pytest.raises((urllib.error.URLError, ConnectionError)):
        scrape(f"http://127.0.0.1:{https.port}/metrics")  # plain HTTP to the TLS port


def test_a_stalled_handshake_does_not_block_scrapes(https: MetricsServer,
                                                    certs: Path) -> None:
    with socket.create_connection(("127.0.0.1", https.port)):  # connects, says nothing
        assert scrape(https.url, client_context(certs)).value("test_things_total") == 3


def test_a_bad_address_names_the_key() -> None:
    with pytest.raises(ConfigError, match=r"x\.yaml: server\.metrics\.listen: 'nowhere' is not "
                                          r"host:port"):
        validate({"server": {"metrics": {"listen": "nowhere"}}}, ServiceConfig, "x.yaml")
    with pytest.raises(ConfigError, match=r"server\.metrics\.listen: Field required"):
        validate({"server": {"metrics": {}}}, ServiceConfig, "x.yaml")


def test_a_missing_certificate_is_a_config_error(tmp_path: Path) -> None:
    config = MetricsConfig.model_validate({"listen": "127.0.0.1:0", "tls": {
        "cert": tmp_path / "none.pem", "key": tmp_path / "none.key"}})
    with pytest.raises(ConfigError, match=r"metrics\.tls\.key: .*none\.key: file not found"):
        MetricsServer(config, CollectorRegistry())


def test_histogram_buckets_are_cumulative_and_inclusive() -> None:
    histogram = LatencyHistogram((0.1, 1.0))
    for seconds in (0.05, 0.1, 0.5, 2.0):
        histogram.observe(seconds)
    buckets, total = histogram.snapshot()
    assert buckets == [("0.1", 2.0), ("1.0", 3.0), ("+Inf", 4.0)]
    assert total == pytest.approx(2.65)
