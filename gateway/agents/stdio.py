"""MCP on standard input and output: the `mcp` SDK's stdio transport, with lines of bounded
length and a JSON-RPC error for each line that is not a message MCP takes.

The SDK's transport reads a whole line however long it is (a client that writes gigabytes
without a newline grows the process without limit), hands a line that is not one JSON-RPC 2.0
message to its dispatcher as an exception, which drops it, and reads a request whose id is
neither an integer nor a string as a notification, which is never answered. Each of those
clients would wait for an answer that never comes. This transport does what the SDK's
`stdio_server` does (the same claim of the standard descriptors, the same validation with the
SDK's own types, the same output), framed and answered as JSON-RPC 2.0 says, and reading goes
on:

- a line over MAX_LINE_BYTES (its newline not counted): -32600 Invalid Request, "line too
  long (N bytes at most)", id null; its bytes are read and dropped up to its newline, never
  held whole;
- text that is not JSON: -32700 Parse error, id null;
- JSON that is not one valid message: -32600 Invalid Request, with the request's id where
  one can be read (an integer, or text that is valid Unicode), else id null;
- a request whose id is null, true or false, a fraction, an object or a list: -32600 Invalid
  Request, id null (MCP's request ids are integers and strings; a notification has no id).

Lines end at "\n" (a "\r" before it is whitespace to JSON), and bytes that are not UTF-8 are
read as U+FFFD, as the SDK reads them.
"""

from __future__ import annotations

import json
import logging
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any, BinaryIO

import anyio
import anyio.lowlevel
import anyio.to_thread
from mcp.server.mcpserver import MCPServer
from mcp.server.stdio import _claim_fd, _open_stdin_diversion, _open_stdout_diversion
from mcp.shared._context_streams import (
    ContextReceiveStream,
    ContextSendStream,
    create_context_streams,
)
from mcp.shared.message import SessionMessage
from mcp_types import (
    INVALID_REQUEST,
    PARSE_ERROR,
    ErrorData,
    JSONRPCError,
    JSONRPCNotification,
    jsonrpc_message_adapter,
)
from pydantic import BaseModel, ValidationError

from oricf.gateway.throttle import ThrottledLog

log = logging.getLogger(__name__)

# The same bound as MCP over HTTP's request body (`oricf mcp --max-request-bytes`' default).
MAX_LINE_BYTES = 16 * 1024 * 1024
# How much of an over-long line is read at a time while it is dropped.
DISCARD_CHUNK_BYTES = 64 * 1024
INVALID_LOG_INTERVAL_S = 10.0
TOO_LONG = f"Invalid Request: line too long ({MAX_LINE_BYTES} bytes at most)"
WRONG_ID = ("Invalid Request: id must be an integer or a string (null, true, false, "
            "fractions, objects and lists are not request ids)")


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


class Envelope(BaseModel):
    """Which members a message has; only its id matters here, whatever its type."""

    id: Any = None


def has_id(text: str) -> bool:
    """Whether a message has an id member: one that the SDK read as a notification then
    carries an id of a type MCP does not allow, and is a request owed an error."""
    try:
        return "id" in Envelope.model_validate_json(text).model_fields_set
    except ValidationError:  # not an object; the SDK read it, so this cannot happen
        return False


def next_line(stdin: BinaryIO) -> bytes | None:
    """The next line as written, its newline kept (b"" at the end of input), or None for a
    line over MAX_LINE_BYTES, whose rest is read and dropped a chunk at a time. Blocks: run
    it in a worker thread."""
    line = stdin.readline(MAX_LINE_BYTES + 1)
    if len(line) <= MAX_LINE_BYTES or line.endswith(b"\n"):
        return line
    del line  # never held beside the rest
    while (rest := stdin.readline(DISCARD_CHUNK_BYTES)) and not rest.endswith(b"\n"):
        pass
    return None


def read_message(line: bytes | None) -> SessionMessage | JSONRPCError:
    """The message a line carries, or the error it is owed."""
    if line is None:
        return error(None, INVALID_REQUEST, TOO_LONG)
    text = line.decode("utf-8", errors="replace")
    try:
        message = jsonrpc_message_adapter.validate_json(text, by_name=False)
    except (ValueError, RecursionError) as exc:  # ValidationError is a ValueError
        return answer(exc)
    if isinstance(message, JSONRPCNotification) and has_id(text):
        return error(None, INVALID_REQUEST, WRONG_ID)
    return SessionMessage(message)


async def read_messages(stdin: BinaryIO, messages: ContextSendStream[SessionMessage],
                        answers: ContextSendStream[SessionMessage]) -> None:
    """Lines to messages for the server until the end of input; errors straight out."""
    throttle = ThrottledLog(log, INVALID_LOG_INTERVAL_S)
    try:
        async with messages:
            while (line := await anyio.to_thread.run_sync(next_line, stdin)) != b"":
                item = read_message(line)
                if isinstance(item, SessionMessage):
                    await messages.send(item)
                    continue
                throttle.warning("invalid", "MCP: a malformed message answered with %d %s",
                                 item.error.code, item.error.message)
                try:
                    await answers.send(SessionMessage(item))
                except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                    log.debug("no answer to a malformed message: the output is closed")
    except anyio.ClosedResourceError:
        await anyio.lowlevel.checkpoint()


async def write_messages(stdout: BinaryIO,
                         outgoing: ContextReceiveStream[SessionMessage]) -> None:
    """Each message as one line of JSON, flushed, as the SDK's transport writes it."""
    def write(data: bytes) -> None:
        stdout.write(data)
        stdout.flush()

    try:
        async with outgoing:
            async for session_message in outgoing:
                text = session_message.message.model_dump_json(by_alias=True,
                                                               exclude_unset=True)
                await anyio.to_thread.run_sync(write, (text + "\n").encode("utf-8"))
    except anyio.ClosedResourceError:
        await anyio.lowlevel.checkpoint()


@asynccontextmanager
async def bounded_stdio() -> AsyncIterator[tuple[ContextReceiveStream[SessionMessage],
                                                 ContextSendStream[SessionMessage]]]:
    """The read and write streams of MCP on this process's standard input and output.

    The descriptors are claimed by the SDK's own claim (fds 0 and 1 point at the null device
    and standard error while serving, and are restored after), so that stray reads and
    prints miss the wire as with the SDK's transport, and a second stdio transport in this
    process is refused."""
    restores: list[Callable[[], None] | None] = []
    try:
        stdin, restore = _claim_fd(0, sys.stdin, "rb", _open_stdin_diversion)
        restores.append(restore)
        stdout, restore = _claim_fd(1, sys.stdout, "wb", _open_stdout_diversion)
        restores.append(restore)
        messages, read_stream = create_context_streams[SessionMessage](0)
        write_stream, outgoing = create_context_streams[SessionMessage](0)
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(read_messages, stdin, messages, write_stream)
            tasks.start_soon(write_messages, stdout, outgoing)
            yield read_stream, write_stream
    finally:
        for restore in reversed(restores):
            if restore is not None:
                restore()


async def serve_stdio(app: MCPServer) -> None:
    """What MCPServer.run("stdio") does, on the bounded, answering transport."""
    server = app._lowlevel_server
    async with bounded_stdio() as (read_stream, write_stream):
        await server.run(read_stream, write_stream, server.create_initialization_options())
