"""What every HTTP request passes before a route sees it, as plain ASGI middleware (so a
streamed answer holds its call slot until its last byte): errors in OpenAI's shape, bearer
tokens, body size and time limits, and the service's call limit.

Order, outermost first: ErrorShape, TokenAuth, BodyLimit, CallSlot. Health checks are
exempt from tokens and the call limit, as on the gRPC side. A call slot is taken only once
the request's body is whole, so clients that send half a body and stall hold none: they hold
a connection until the body's deadline, and are then answered 408 and disconnected.
"""

from __future__ import annotations

import asyncio
import codecs
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
# Form fields in these charsets are text; in others (unicode_escape, say) the form parser
# could make strings that are not (lone surrogates).
FORM_CHARSETS = frozenset({"utf-8", "ascii", "iso8859-1"})
FORM_TYPES = ("multipart/form-data", "application/x-www-form-urlencoded")


def header(scope: Scope, name: bytes) -> str | None:
    for key, value in scope.get("headers", ()):
        if key == name:
            return str(value.decode("latin-1"))
    return None


def has_body(scope: Scope) -> bool:
    length = header(scope, b"content-length")
    return header(scope, b"transfer-encoding") is not None or (
        length is not None and length.strip() != "0")


class ErrorShape:
    """Turns any exception into an OpenAI-shaped error answer, never a traceback."""

    def __init__(self, app: Any, limit: CallLimit) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        state = {"started": False, "body_done": not has_body(scope)}

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
            response = error_response(error)
            if not state["body_done"]:
                # The rest of the body is not read (for a 413 or a 408 that is the point):
                # the connection ends with the answer, closed lingering (server.py).
                response.headers["connection"] = "close"
            log.debug("%s %s -> %d: %s", scope["method"], scope["path"], error.status,
                      error.message)
            await response(scope, receive, send)


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
    """Refuses bodies over the limit (413), bodies not sent within the deadline (408) and
    forms in a charset that is not UTF-8 (400).

    The limit is the upload limit for multipart bodies (files), the body limit otherwise; a
    Content-Length over it is refused at once, before any byte is read, and a body that
    turns out longer than it said or than the limit (a chunked one) is cut off when it
    crosses the limit. Either way the connection is closed after the answer (ErrorShape).
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
        check_form_charset(header(scope, b"content-type") or "")
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


def check_form_charset(content_type: str) -> None:
    """A form body declared in a charset other than UTF-8 (or ASCII, Latin-1): 400."""
    kind, _, options = content_type.partition(";")
    if kind.strip().lower() not in FORM_TYPES:
        return
    for option in options.split(";"):
        name, _, value = option.partition("=")
        if name.strip().lower() != "charset":
            continue
        charset = value.strip().strip('"')
        try:
            known = codecs.lookup(charset).name in FORM_CHARSETS
        except LookupError:
            known = False
        if not known:
            raise ApiError(400, f"content-type: charset '{charset[:40]}' is not read here; "
                                f"send form fields in UTF-8", param="content-type")


class CallSlot:
    """Holds one of the service's call slots (server.max_concurrent_rpcs, shared with gRPC)
    for each POST from the moment its body is whole until its answer has been sent; none
    free then: 429 with Retry-After. A client still sending its body holds none (its
    deadline is BodyLimit's), so stalled half-sent bodies cannot lock out other callers,
    over HTTP or gRPC."""

    def __init__(self, app: Any, limit: CallLimit) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST":
            await self.app(scope, receive, send)
            return
        held = False

        async def receive_then_enter() -> Any:
            nonlocal held
            message = await receive()
            whole = message["type"] == "http.request" and not message.get("more_body", False)
            if whole and not held:
                self._enter()
                held = True
            return message

        try:
            await self.app(scope, receive_then_enter, send)
        finally:
            if held:
                self.limit.leave()

    def _enter(self) -> None:
        if not self.limit.try_enter():
            wait_ms = self.limit.pushback_ms()
            raise ApiError(429, f"the service is busy ({self.limit.limit} calls in progress); "
                                f"retry in {wait_ms} ms", code="rate_limit_exceeded",
                           retry_after_ms=wait_ms)
