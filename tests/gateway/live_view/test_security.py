"""The live view opened beyond loopback: wss:// and bearer tokens, checked by the front
before the upgrade; the official client connects with its token, others are refused."""

from __future__ import annotations

import logging
import socket
import ssl
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from oricf.errors import ConfigError
from oricf.gateway.listeners import LiveViewConfig
from tests.gateway.live_view.support import Running, running, video_pipeline
from tests.gateway.live_view.viewers import official_client
from tests.support.certs import TOKEN
from tests.support.services import RunningService, running_service


@pytest.fixture(scope="module")
def secured(certs: Path, detector: RunningService) -> Iterator[Running]:
    with running(video_pipeline(
            detector.address, {"tls": {"cert": str(certs / "server.pem"),
                                       "key": str(certs / "server.key")},
                               "auth": {"file": str(certs / "tokens")}})) as run:
        yield run


def client_tls(certs: Path) -> ssl.SSLContext:
    return ssl.create_default_context(cafile=str(certs / "ca.pem"))


def test_the_official_client_connects_over_wss_with_its_token(secured: Running,
                                                              certs: Path) -> None:
    assert secured.url.startswith("wss://127.0.0.1:")
    got = official_client(secured.url, seconds=4, token=TOKEN, ca=certs / "ca.pem")
    assert got.topics["/people/image"] == "foxglove.CompressedImage"
    assert got.messages["/people/image"]


@pytest.mark.parametrize("token", [None, "wrong-token", TOKEN[:-1]])
def test_a_viewer_without_the_token_is_refused_before_the_upgrade(
        secured: Running, certs: Path, token: str | None) -> None:
    headers = {"Authorization": f"Bearer {token}"} if token else None
    with pytest.raises(InvalidStatus) as refused:
        connect(secured.url, ssl=client_tls(certs), additional_headers=headers,
                subprotocols=["foxglove.sdk.v1"])  # type: ignore[list-item]
    assert refused.value.response.status_code == 401


def test_a_browser_passes_the_token_in_the_url_and_no_token_is_logged(
        secured: Running, certs: Path, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.DEBUG):
        with connect(f"{secured.url}/?token={TOKEN}", ssl=client_tls(certs),
                     subprotocols=["foxglove.websocket.v1"]) as viewer:  # type: ignore[list-item]
            assert '"op":"serverInfo"' in str(viewer.recv(timeout=5))
        with pytest.raises(InvalidStatus):
            connect(f"{secured.url}/?token=guessed-{TOKEN}", ssl=client_tls(certs),
                    subprotocols=["foxglove.sdk.v1"])  # type: ignore[list-item]
        with connect(secured.url, ssl=client_tls(certs), subprotocols=["foxglove.sdk.v1"],  # type: ignore[list-item]
                     additional_headers={"Authorization": f"Bearer {TOKEN}"}) as viewer:
            viewer.recv(timeout=5)
    gateway = [r.getMessage() for r in caplog.records  # this test's own client aside
               if not r.name.startswith("websockets.client")]
    assert gateway and not any(TOKEN in line for line in gateway)


def test_plain_ws_to_the_tls_port_gets_nothing(secured: Running) -> None:
    with pytest.raises(Exception):  # noqa: B017 - any failure: no TLS, no answer
        connect(secured.url.replace("wss://", "ws://"), open_timeout=5,
                subprotocols=["foxglove.sdk.v1"])  # type: ignore[list-item]


def test_listening_beyond_loopback_needs_tls_and_a_token(certs: Path) -> None:
    tls = {"cert": certs / "server.pem", "key": certs / "server.key"}
    for partial in ({}, {"tls": tls}, {"auth": {"file": certs / "tokens"}}):
        with pytest.raises(ValueError, match=r"set both tls and auth, or listen on 127\.0\.0\.1"):
            LiveViewConfig.model_validate({"listen": "0.0.0.0:8765", **partial})
    LiveViewConfig.model_validate({"listen": "0.0.0.0:8765", "tls": tls,
                                   "auth": {"file": certs / "tokens"}})
    for loopback in ("127.0.0.1:8765", "[::1]:8765", "localhost:8765"):
        LiveViewConfig.model_validate({"listen": loopback})


def test_a_port_in_use_fails_the_start_with_a_clear_error(detector_address: str) -> None:
    with running(video_pipeline(detector_address)) as first:
        port = first.url.rsplit(":", 1)[1]
        config = video_pipeline(detector_address, {"listen": f"127.0.0.1:{port}"})
        with pytest.raises(ConfigError, match=f"foxglove: cannot listen on 127.0.0.1:{port}"), \
                running(config):
            pass


@pytest.fixture()
def detector_address() -> Iterator[str]:
    with running_service("detector", load=False) as detector:
        yield detector.address




def test_a_connection_that_never_starts_tls_is_closed(secured: Running) -> None:
    host, port = secured.url.removeprefix("wss://").rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=30) as idle:
        started = time.monotonic()
        assert idle.recv(1) == b""  # closed by the server
    assert time.monotonic() - started < 25  # the handshake deadline (10 s), not asyncio's 60
