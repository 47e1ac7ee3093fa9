"""Errors of the HTTP API in OpenAI's shape, mapped from the domain errors in one place.

    {"error": {"message": "...", "type": "invalid_request_error", "param": null, "code": null}}

The same domain errors the gRPC side maps (services/runtime/errors.py) get the HTTP status
an OpenAI client expects: InvalidInput 400, NotFound 404, Overloaded 429 (with Retry-After),
NotReady 503. Anything unexpected is logged with its traceback and answered 500 without
internals. Messages are cut as on the gRPC side, since they may echo caller input, and
whatever they echo is made encodable first (a lone UTF-16 surrogate cannot be written as
UTF-8), so building an error answer cannot fail and it is always JSON.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect
from starlette.responses import JSONResponse

from oricf.errors import (
    Cancelled,
    DeadlineExceeded,
    InvalidInput,
    NotFound,
    NotReady,
    Overloaded,
)
from oricf.services.runtime.errors import INTERNAL_MESSAGE, MAX_MESSAGE

log = logging.getLogger(__name__)

# What a client that went away "gets": nothing, but the metrics and logs need a status.
CLIENT_CLOSED = 499

# domain error -> (HTTP status, OpenAI error type, code)
STATUS_FOR: dict[type[Exception], tuple[int, str, str | None]] = {
    InvalidInput: (400, "invalid_request_error", None),
    NotFound: (404, "invalid_request_error", "not_found"),
    Overloaded: (429, "rate_limit_error", "rate_limit_exceeded"),
    NotReady: (503, "service_unavailable", "not_ready"),
    DeadlineExceeded: (504, "timeout", "deadline_exceeded"),
    Cancelled: (CLIENT_CLOSED, "cancelled", "client_closed_request"),
}
TYPE_FOR_STATUS = {400: "invalid_request_error", 401: "authentication_error",
                   404: "invalid_request_error", 405: "invalid_request_error",
                   408: "timeout", 413: "invalid_request_error", 429: "rate_limit_error",
                   500: "server_error", 503: "service_unavailable"}


class InvalidParam(InvalidInput):
    """Bad input in one field of an HTTP request body, named as OpenAI's `param`."""

    def __init__(self, message: str, param: str | None = None) -> None:
        super().__init__(message)
        self.param = param


class ApiError(Exception):
    """An HTTP-side refusal that has no domain error of its own (401, 408, 413)."""

    def __init__(self, status: int, message: str, *, param: str | None = None,
                 code: str | None = None, retry_after_ms: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
        self.param = param
        self.code = code
        self.retry_after_ms = retry_after_ms


def _cut(message: str) -> str:
    return message if len(message) <= MAX_MESSAGE else message[:MAX_MESSAGE] + "... (cut)"


def printable(text: str) -> str:
    """text with what UTF-8 cannot encode (lone surrogates) written as escapes: an error
    that echoes caller input must still be sendable."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def error_body(status: int, message: str, *, kind: str | None = None,
               param: str | None = None, code: str | None = None) -> dict[str, Any]:
    return {"error": {"message": _cut(printable(message)),
                      "type": kind or TYPE_FOR_STATUS.get(status, "invalid_request_error"),
                      "param": None if param is None else _cut(printable(param)),
                      "code": code}}


def as_api_error(exc: BaseException, retry_after_ms: int) -> ApiError:
    """Any exception as the ApiError a client sees; unexpected ones are logged here."""
    if isinstance(exc, ApiError):
        return exc
    if isinstance(exc, HTTPException):
        return ApiError(exc.status_code, str(exc.detail))
    if isinstance(exc, ClientDisconnect):  # while its body was being read
        return ApiError(CLIENT_CLOSED, "the client went away", code="client_closed_request")
    for kind, (status, _, code) in STATUS_FOR.items():
        if isinstance(exc, kind):
            wait = None
            if status == 429:
                wait = getattr(exc, "retry_after_ms", None) or retry_after_ms
            return ApiError(status, str(exc) or kind.__name__, code=code, retry_after_ms=wait,
                            param=getattr(exc, "param", None))
    log.error("unexpected error in an HTTP request", exc_info=exc)
    return ApiError(500, INTERNAL_MESSAGE, code="internal_error")


def error_response(error: ApiError) -> JSONResponse:
    kind = next((t for s, t, _ in STATUS_FOR.values() if s == error.status), None)
    headers = {}
    if error.retry_after_ms is not None:
        # Retry-After is whole seconds; OpenAI's clients read the finer retry-after-ms first.
        headers["Retry-After"] = str(max(1, math.ceil(error.retry_after_ms / 1000)))
        headers["retry-after-ms"] = str(error.retry_after_ms)
    body = error_body(error.status, error.message, kind=kind, param=error.param,
                      code=error.code)
    return JSONResponse(body, status_code=error.status, headers=headers)
