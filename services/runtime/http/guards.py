"""What every HTTP request passes before a route sees it, as plain ASGI middleware (so a
streamed answer holds its call slot until its last byte): errors in OpenAI's shape, bearer
tokens, body size and time limits, and the service's call limit.

Order, outermost first: ErrorShape, TokenAuth, BodyLimit, CallSlot. Health checks are
exempt from tokens and the call limit, as on the gRPC side.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from typing import Any

from oricf.services.runtime.http.errors import ApiError, as_api_error, error_response
from oricf.services.runtime.limits import CallLimit
from oricf.tls import token_matches

log = logging.getLogger(__name__)

Scope = dict[str, Any]
Receive = Any
Send = Any

HEALTH_PATH = "/health"
# An error answer is sent once the client's body is read (closing a socket with unread
# bytes resets it, and the client would see a reset instead of the answer); at most this
# much is read and thrown away for it.
DRAIN_LIMIT = 64 * 1024 * 1024


def header(scope: Scope, name: bytes) -> str | None:
    for key, value in scope.get("headers", ()):
        if key == name:
            return str(value.decode("latin-1"))
    return None


class ErrorShape:
    """Turns any exception into an OpenAI-shaped error answer, never a traceback."""

    def __init__(self, app: Any, limit: CallLimit, drain_timeout_s: float) -> None:
        self.app = app
        self.limit = limit
        self.drain_timeout_s = drain_timeout_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        state = {"started": False, "body_done": False}

        async def tracked_receive() -> Any:
            message = await receive()
            if message["type"] != "http.request" or not message.get("more_body", False):
                state["body_done"] = True
            return message

        async def tracked_send(message: Any) -> None:
            if message["type"] == "http.response.start":
                state["started"] = True
            await send(message)

        try:
            await self.app(scope, tracked_receive, tracked_send)
        except Exception as exc:
            error = as_api_error(exc, self.limit.pushback_ms())
            if state["started"]:  # mid-stream: the route already said what it could
                log.debug("%s: ended mid-answer: %s", scope["path"], error.message)
                return
            if not state["body_done"]:
                await self._drain(receive)
            log.debug("%s %s -> %d: %s", scope["method"], scope["path"], error.status,
                      error.message)
            await error_response(error)(scope, receive, send)

    async def _drain(self, receive: Receive) -> None:
        """Reads what is left of the body, within the time and byte limits."""
        deadline = time.monotonic() + self.drain_timeout_s
        read = 0
        try:
            while read < DRAIN_LIMIT:
                message = await asyncio.wait_for(receive(), deadline - time.monotonic())
                read += len(message.get("body", b""))
                if message["type"] != "http.request" or not message.get("more_body", False):
                    return
        except (asyncio.TimeoutError, ValueError):
            return


class TokenAuth:
    """`Authorization: Bearer TOKEN`, compared in constant time; tokens are never logged."""

    def __init__(self, app: Any, tokens: Sequence[str]) -> None:
        self.app = app
        self._tokens = [token.encode() for token in tokens]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["path"] != HEALTH_PATH:
            value = header(scope, b"authorization")
            if value is None:
                raise ApiError(401, "authorization: Bearer TOKEN needed",
                               code="missing_api_key")
            scheme, _, token = value.partition(" ")
            if scheme.lower() != "bearer" or not token_matches(token.strip(), self._tokens):
                raise ApiError(401, "the token is not accepted", code="invalid_api_key")
        await self.app(scope, receive, send)


class BodyLimit:
    """Refuses bodies over the limit (413) and bodies not sent within the deadline (408).

    The limit is the upload limit for multipart bodies (files), the body limit otherwise; a
    Content-Length over it is refused before any byte is read, and a body that turns out
    longer than it said or than the limit is cut off when it crosses the limit.
    """

    def __init__(self, app: Any, max_body: int, max_upload: int, timeout_s: float) -> None:
        self.app = app
        self.max_body = max_body
        self.max_upload = max_upload
        self.timeout_s = timeout_s

    def _limit(self, scope: Scope) -> int:
        kind = header(scope, b"content-type") or ""
        return self.max_upload if kind.startswith("multipart/form-data") else self.max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self._limit(scope)
        declared = header(scope, b"content-length")
        if declared is not None and declared.strip().isdigit() and int(declared) > limit:
            raise ApiError(413, f"the request body of {int(declared):,} bytes is over this "
                                f"service's limit of {limit:,} bytes", code="request_too_large")
        deadline = time.monotonic() + self.timeout_s
        received = 0
        done = False

        async def limited_receive() -> Any:
            nonlocal received, done
            if done:  # after the body: disconnect notices, waited for as long as it takes
                return await receive()
            try:
                message = await asyncio.wait_for(receive(), max(0.0, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                raise ApiError(408, f"the request body did not arrive within "
                                    f"{self.timeout_s:g} s", code="request_timeout") from None
            received += len(message.get("body", b""))
            if received > limit:
                raise ApiError(413, f"the request body is over this service's limit of "
                                    f"{limit:,} bytes", code="request_too_large")
            if message["type"] != "http.request" or not message.get("more_body", False):
                done = True
            return message

        await self.app(scope, limited_receive, send)


class CallSlot:
    """Holds one of the service's call slots (server.max_concurrent_rpcs, shared with gRPC)
    for each POST, until its answer has been sent; none free: 429 with Retry-After."""

    def __init__(self, app: Any, limit: CallLimit) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST":
            await self.app(scope, receive, send)
            return
        if not self.limit.try_enter():
            wait_ms = self.limit.pushback_ms()
            raise ApiError(429, f"the service is busy ({self.limit.limit} calls in progress); "
                                f"retry in {wait_ms} ms", code="rate_limit_exceeded",
                           retry_after_ms=wait_ms)
        try:
            await self.app(scope, receive, send)
        finally:
            self.limit.leave()
