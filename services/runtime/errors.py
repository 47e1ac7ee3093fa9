"""Domain errors -> gRPC status codes, in one place, for every service.

ErrorMappingInterceptor wraps every handler of a server: a servicer raises InvalidInput
(or lets a model raise it) and the caller gets INVALID_ARGUMENT with the message. Anything
unexpected is logged with its traceback and returned as INTERNAL without internals.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

import grpc

from oricf.errors import (
    Cancelled,
    DeadlineExceeded,
    InvalidInput,
    NotFound,
    NotReady,
    Overloaded,
)

log = logging.getLogger(__name__)

STATUS_FOR: dict[type[Exception], grpc.StatusCode] = {
    InvalidInput: grpc.StatusCode.INVALID_ARGUMENT,
    NotFound: grpc.StatusCode.NOT_FOUND,
    NotReady: grpc.StatusCode.UNAVAILABLE,
    Overloaded: grpc.StatusCode.RESOURCE_EXHAUSTED,
    DeadlineExceeded: grpc.StatusCode.DEADLINE_EXCEEDED,
    Cancelled: grpc.StatusCode.CANCELLED,
}

INTERNAL_MESSAGE = "internal error in the service (details are in its log)"


def status_for(exc: BaseException, method: str = "") -> tuple[grpc.StatusCode, str]:
    """The status code and caller-facing message for an exception."""
    for kind, code in STATUS_FOR.items():
        if isinstance(exc, kind):
            return code, str(exc) or kind.__name__
    log.error("unexpected error in %s", method or "a call", exc_info=exc)
    return grpc.StatusCode.INTERNAL, INTERNAL_MESSAGE


def check_deadline(context: grpc.ServicerContext,
                   when: str = "before the call could start") -> None:
    """Refuses work whose caller has already given up."""
    remaining = context.time_remaining()
    if remaining is not None and remaining <= 0:
        raise DeadlineExceeded(f"the deadline passed {when}")


def _already_aborted(context: grpc.ServicerContext) -> bool:
    code = getattr(context, "code", None)
    return callable(code) and code() not in (None, grpc.StatusCode.OK)


def _abort(context: grpc.ServicerContext, exc: Exception, method: str) -> None:
    if _already_aborted(context):
        raise exc
    code, message = status_for(exc, method)
    log.debug("%s -> %s: %s", method, code.name, message)
    context.abort(code, message)


def _wrap_unary_response(behavior: Callable[..., Any], method: str) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Any:
        try:
            check_deadline(context)
            return behavior(request, context)
        except Exception as exc:
            _abort(context, exc, method)

    return handler


def _wrap_stream_response(behavior: Callable[..., Any], method: str) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Iterator[Any]:
        try:
            check_deadline(context)
            yield from behavior(request, context)
        except Exception as exc:
            _abort(context, exc, method)

    return handler


class ErrorMappingInterceptor(grpc.ServerInterceptor):
    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        handler_call_details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        handler = continuation(handler_call_details)
        if handler is None:
            return None
        method = handler_call_details.method
        if handler.unary_unary:
            return handler._replace(unary_unary=_wrap_unary_response(handler.unary_unary, method))
        if handler.stream_unary:
            return handler._replace(
                stream_unary=_wrap_unary_response(handler.stream_unary, method))
        if handler.unary_stream:
            return handler._replace(
                unary_stream=_wrap_stream_response(handler.unary_stream, method))
        if handler.stream_stream:
            return handler._replace(
                stream_stream=_wrap_stream_response(handler.stream_stream, method))
        return handler
