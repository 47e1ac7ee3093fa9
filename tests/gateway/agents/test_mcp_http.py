"""`oricf mcp --transport http`: streamable HTTP with bearer tokens, driven by the `mcp`
SDK's own HTTP client, against a real gateway and real models; commands reach a real rclpy
subscriber."""

from __future__ import annotations

import socket
import ssl
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio
import httpx
import pytest

from tests.gateway.agents.scene import PEOPLE, RosListener
from tests.gateway.agents.session import (
    TOOLS,
    http_session,
    server_env,
    text_of,
    wait_product,
    warm_up,
)
from tests.support.certs import TOKEN
from tests.support.processes import free_port


@contextmanager
def mcp_http(*args: str, log: Path) -> Iterator[subprocess.Popen[bytes]]:
    """`oricf mcp ... --transport http`; its log into a file (a pipe nobody reads fills)."""
    with log.open("wb") as out:
        process = subprocess.Popen([sys.executable, "-m", "oricf", "mcp", *args,
                                    "--transport", "http"], stdout=out,
                                   stderr=subprocess.STDOUT, env=server_env(),
                                   start_new_session=True)
    try:
        yield process
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)


def wait_listening(port: int, process: subprocess.Popen[bytes], log: Path) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert process.poll() is None, log.read_text()
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(log.read_text())


@pytest.fixture()
def server(pipeline: Path, tmp_path: Path) -> Iterator[str]:
    tokens = tmp_path / "tokens"
    tokens.write_text(f"{TOKEN}\n")
    port = free_port()
    log = tmp_path / "mcp.log"
    with mcp_http("--config", str(pipeline), "--listen", f"127.0.0.1:{port}",
                  "--auth-token-file", str(tokens), log=log) as process:
        wait_listening(port, process, log)
        yield f"http://127.0.0.1:{port}/mcp"


def test_http_with_tokens(server: str, driver: RosListener) -> None:
    refused = httpx.post(server, json={"jsonrpc": "2.0", "id": 1, "method": "tools/list"},
                         headers={"Authorization": "Bearer wrong"})
    assert refused.status_code == 401
    assert httpx.post(server, json={}).status_code == 401

    async def scenario() -> None:
        async with http_session(server, TOKEN) as session:
            assert {t.name for t in (await session.list_tools()).tools} == TOOLS
            assert (await wait_product(session, "people_count"))["value"] == PEOPLE
            look = await session.call_tool("look", {"route": "people"})
            assert look.structured_content is not None
            assert look.structured_content["counts"] == {"person": PEOPLE}

            await warm_up(session, "cmd_vel", driver.twists)
            await anyio.sleep(0.6)
            driver.drain()
            sent = await session.call_tool("publish", {"target": "cmd_vel",
                                                       "message": {"angular": {"z": 0.9}}})
            assert not sent.is_error, text_of(sent)
            assert driver.twists.get(timeout=10).angular.z == 0.5  # clamped
            outside = await session.call_tool("publish", {"target": "gripper", "message": {}})
            assert outside.is_error and "not a target" in text_of(outside)
            # no client here can answer an elicitation: approval is not given
            arm = await session.call_tool("publish", {"target": "arm", "message": {"data": 0.1}})
            assert arm.is_error and "approval" in text_of(arm)
            bad = await session.call_tool("look", {"route": ["people"]})
            assert bad.is_error
            assert not (await session.call_tool("status", {})).is_error

    anyio.run(scenario)


def test_https_with_tokens(pipeline: Path, tmp_path: Path, certs: Path) -> None:
    port = free_port()
    log = tmp_path / "mcp.log"
    with mcp_http("--config", str(pipeline), "--listen", f"127.0.0.1:{port}",
                  "--auth-token-file", str(certs / "tokens"), "--tls-cert",
                  str(certs / "server.pem"), "--tls-key", str(certs / "server.key"),
                  log=log) as process:
        wait_listening(port, process, log)
        url = f"https://127.0.0.1:{port}/mcp"
        with pytest.raises(httpx.ConnectError):  # a client that does not trust the CA
            httpx.post(url, json={})

        async def scenario() -> None:
            context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
            async with http_session(url, TOKEN, verify=context) as session:
                count = await wait_product(session, "people_count")
                assert count["value"] == PEOPLE

        anyio.run(scenario)
    assert TOKEN not in log.read_text()


def test_beyond_this_machine_needs_tokens_and_tls(pipeline: Path, tmp_path: Path) -> None:
    log = tmp_path / "mcp.log"
    with mcp_http("--config", str(pipeline), "--listen", "0.0.0.0:0", log=log) as process:
        assert process.wait(timeout=60) == 2
    assert "needs --auth-token-file and --tls-cert" in log.read_text()
