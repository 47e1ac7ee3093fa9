"""MCP on standard input and output: the `mcp` SDK's stdio transport, with a JSON-RPC error
for each line it cannot read as a message.

The SDK's transport hands a line that is not one JSON-RPC 2.0 message to its dispatcher as
an exception, and the dispatcher drops it: a client that sent a batch, a request without a
method, with `"jsonrpc": "1.0"`, a number for a method, params that are a list, or text that
is not valid Unicode would wait for an answer that never comes. A thin wrapper around that
read stream answers each one as JSON-RPC 2.0 says, and reading goes on:

- text that is not JSON: -32700 Parse error, id null;
- JSON that is not one valid message: -32600 Invalid Request, with the request's id where
  one can be read (an integer, or text that is valid Unicode), else id null.
"""

from __future__ import annotations

import json
import logging
from types import TracebackType
from typing import Any

import anyio
from mcp.server.mcpserver import MCPServer
from mcp.server.stdio import stdio_server
from mcp.shared._stream_protocols import ReadStream, WriteStream
from mcp.shared.message import SessionMessage
from mcp_types import INVALID_REQUEST, PARSE_ERROR, ErrorData, JSONRPCError
from pydantic import ValidationError

from oricf.gateway.throttle import ThrottledLog

log = logging.getLogger(__name__)

INVALID_LOG_INTERVAL_S = 10.0
Item = SessionMessage | Exception


def readable_id(message: Any) -> int | str | None:
    """The id of a request, if it has one that an answer can carry."""
    if not isinstance(message, dict):
        return None
    found = message.get("id")
    if isinstance(found, int) and not isinstance(found, bool):
        return found
    if isinstance(found, str):
        try:
            found.encode("utf-8")  # a lone surrogate cannot be written back
        except UnicodeEncodeError:
            return None
        return found
    return None


def error(request_id: int | str | None, code: int, message: str) -> JSONRPCError:
    return JSONRPCError(jsonrpc="2.0", id=request_id, error=ErrorData(code=code,
                                                                      message=message))


def unreadable_json(text: str, why: str) -> JSONRPCError:
    """A line the SDK's JSON parser refused. Python's parser also takes what the JSON grammar
    allows and Unicode does not (a lone surrogate), so its id can still be answered."""
    try:
        message = json.loads(text)
    except (ValueError, RecursionError):
        return error(None, PARSE_ERROR, "Parse error: the line is not JSON")
    return error(readable_id(message), INVALID_REQUEST, f"Invalid Request: {why}")


def answer(exc: Exception) -> JSONRPCError:
    """The error owed for a line that the transport could not read as a message."""
    if not isinstance(exc, ValidationError):
        return error(None, INVALID_REQUEST, "Invalid Request: not a JSON-RPC 2.0 message")
    problems = exc.errors(include_url=False)
    for problem in problems:
        if problem["type"] == "json_invalid":
            return unreadable_json(str(problem["input"]), problem["msg"])
    # A field that some kind of message lacks is reported with the whole message as input.
    message = next((p["input"] for p in problems
                    if p["type"] == "missing" and len(p["loc"]) == 2), None)
    if message is None and problems and isinstance(problems[0]["input"], list):
        return error(None, INVALID_REQUEST,
                     "Invalid Request: a batch; MCP takes one message a line")
    as_request = [f"{p['loc'][1]}: {p['msg']}" for p in problems
                  if len(p["loc"]) == 2 and p["loc"][0] == "JSONRPCRequest"]
    why = "; ".join(as_request) or "not a JSON-RPC 2.0 message"
    return error(readable_id(message), INVALID_REQUEST, f"Invalid Request: {why}")


class AnsweringReadStream:
    """The transport's read stream, less what it could not read: each of those is answered
    on the write stream instead of reaching the dispatcher, which would drop it."""

    def __init__(self, inner: ReadStream[Item], answers: WriteStream[SessionMessage]) -> None:
        self._inner = inner
        self._answers = answers
        self._throttle = ThrottledLog(log, INVALID_LOG_INTERVAL_S)

    @property
    def last_context(self) -> Any:
        """The sender's context of the last message (the SDK's context-aware streams)."""
        return getattr(self._inner, "last_context", None)

    async def receive(self) -> Item:
        while True:
            item = await self._inner.receive()
            if not isinstance(item, Exception):
                return item
            reply = answer(item)
            self._throttle.warning("invalid", "MCP: a malformed message answered with %d %s",
                                   reply.error.code, reply.error.message)
            try:
                await self._answers.send(SessionMessage(reply))
            except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                log.debug("no answer to a malformed message: the output is closed")

    async def aclose(self) -> None:
        await self._inner.aclose()

    def __aiter__(self) -> AnsweringReadStream:
        return self

    async def __anext__(self) -> Item:
        try:
            return await self.receive()
        except anyio.EndOfStream:
            raise StopAsyncIteration from None

    async def __aenter__(self) -> AnsweringReadStream:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.aclose()


async def serve_stdio(app: MCPServer) -> None:
    """What MCPServer.run("stdio") does, with malformed messages answered."""
    server = app._lowlevel_server
    async with stdio_server() as (read_stream, write_stream):
        await server.run(AnsweringReadStream(read_stream, write_stream), write_stream,
                         server.create_initialization_options())
