"""The address the control API reports is one a client can use: a URL, with an IPv6 host
in brackets."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from oricf.gateway.api.server import ControlServer
from oricf.gateway.listeners import ControlConfig


@pytest.mark.parametrize(("listen", "host"), [("127.0.0.1:0", "127.0.0.1"), ("[::1]:0", "[::1]")])
def test_the_reported_address_is_a_url_a_client_can_use(listen: str, host: str,
                                                         tmp_path: Path) -> None:
    tokens = tmp_path / "tokens"
    tokens.write_text("s3cret\n")
    server = ControlServer(ControlConfig.model_validate(
        {"listen": listen, "auth": {"file": str(tokens)}}), gateway=None)  # type: ignore[arg-type]
    sock = server._socket()
    try:
        url = httpx.URL(server.address)
        assert server.address.startswith(f"http://{host}:")
        assert url.port == sock.getsockname()[1] and url.port > 0
    finally:
        sock.close()
