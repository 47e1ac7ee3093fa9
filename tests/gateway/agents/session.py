"""Sessions of the `mcp` SDK's own client with `oricf mcp`, over stdio and streamable HTTP,
and what the agent tests do with them."""

from __future__ import annotations

import os
import ssl
import sys
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import httpx2
import mcp_types as types
from mcp import ClientSession, StdioServerParameters
from mcp.client.stdio import stdio_client
from mcp.client.streamable_http import streamable_http_client
from mcp.shared._httpx_utils import create_mcp_http_client

TOOLS = {"list_products", "read_product", "look", "detect", "infer", "ask", "transcribe",
         "say", "status", "publish"}


def server_env() -> dict[str, str]:
    """The whole environment (the SDK passes only a safe subset by default): the test's
    private ROS domain must reach the server."""
    return {**os.environ, "ORICF_LOG_LEVEL": "INFO"}


Elicit = Any


@asynccontextmanager
async def stdio_session(*args: str, elicit: Elicit = None, on_message: Any = None
                        ) -> AsyncIterator[ClientSession]:
    """`oricf mcp ARGS` launched as a desktop agent launches it, and a session with it."""
    params = StdioServerParameters(command=sys.executable, args=["-m", "oricf", "mcp", *args],
                                   env=server_env())
    async with stdio_client(params) as (read, write), \
            ClientSession(read, write, elicitation_callback=elicit,
                          message_handler=on_message) as session:
        await session.initialize()
        yield session


@asynccontextmanager
async def http_session(url: str, token: str | None, elicit: Elicit = None,
                       verify: ssl.SSLContext | None = None) -> AsyncIterator[ClientSession]:
    """A session over streamable HTTP, with a bearer token (and a CA to trust)."""
    headers = {"Authorization": f"Bearer {token}"} if token else None
    http_client = (create_mcp_http_client(headers=headers) if verify is None else
                   httpx2.AsyncClient(headers=headers, verify=verify, timeout=60))
    async with http_client as http, \
            streamable_http_client(url, http_client=http) as (read, write), \
            ClientSession(read, write, elicitation_callback=elicit) as session:
        await session.initialize()
        yield session


async def wait_product(session: ClientSession, name: str, timeout: float = 60.0
                       ) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        result = await session.call_tool("read_product", {"name": name})
        if not result.is_error:
            assert result.structured_content is not None
            return result.structured_content
        if time.monotonic() > deadline:
            raise TimeoutError(result.content)
        await anyio.sleep(0.5)


def text_of(result: types.CallToolResult) -> str:
    return " ".join(c.text for c in result.content if isinstance(c, types.TextContent))



async def warm_up(session: ClientSession, target: str, received: Any) -> None:
    """Zero commands until one arrives: DDS discovery is complete both ways."""
    deadline = time.monotonic() + 20
    while received.empty():
        assert time.monotonic() < deadline, f"nothing sent to {target} arrived"
        await session.call_tool("publish", {"target": target, "message": {}})
        await anyio.sleep(0.6)


