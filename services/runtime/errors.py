"""Domain errors -> gRPC status codes, in one place, for every service.

ErrorMappingInterceptor wraps every handler of a server. Requests are parsed inside it, so
bytes that are not the request message get INVALID_ARGUMENT like any bad input; a servicer
raises InvalidInput (or lets a model raise it) and the caller gets INVALID_ARGUMENT with the
message. Anything unexpected is logged with its traceback and returned as INTERNAL without
internals. Calls over the service's limit are refused here too, with retry pushback.
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
from oricf.services.runtime.limits import EXEMPT_STREAMS, PUSHBACK_KEY, CallLimit, exempt
from oricf.services.runtime.streams import (
    MessageStreams,
    OpenStreams,
    idle_bounded,
    per_message,
)
from oricf.v1 import common_pb2

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
# Status messages travel in trailing metadata (8 KB by default) and may echo caller input:
# longer ones are cut, so a huge label is still answered INVALID_ARGUMENT.
MAX_MESSAGE = 1000


def status_for(exc: BaseException, method: str = "") -> tuple[grpc.StatusCode, str]:
    """The status code and caller-facing message for an exception."""
    for kind, code in STATUS_FOR.items():
        if isinstance(exc, kind):
            message = str(exc) or kind.__name__
            if len(message) > MAX_MESSAGE:
                message = message[:MAX_MESSAGE] + "... (cut)"
            return code, message
    log.error("unexpected error in %s", method or "a call", exc_info=exc)
    return grpc.StatusCode.INTERNAL, INTERNAL_MESSAGE


# What refuses one message of a stream without ending it: a bad frame or observation, or
# one that does not fit the memory budget now.
MESSAGE_REFUSALS = (InvalidInput, Overloaded)


def refusal(exc: Exception) -> common_pb2.Error:
    """A refused message's answer: the status code and message its call would have had."""
    code, message = status_for(exc)
    return common_pb2.Error(code=code.value[0], message=message)


def check_deadline(context: grpc.ServicerContext,
                   when: str = "before the call could start") -> None:
    """Refuses work whose caller has already given up."""
    remaining = context.time_remaining()
    if remaining is not None and remaining <= 0:
        raise DeadlineExceeded(f"the deadline passed {when}")


def check_wanted(context: grpc.ServicerContext, when: str,
                 gone: str = "the caller went away") -> None:
    """Between pieces of work (tokens, sentences, audio chunks): stops when the deadline
    has passed or the caller has gone, so nobody's work goes on for no one."""
    check_deadline(context, when)
    if not context.is_active():
        raise Cancelled(gone)


def _already_aborted(context: grpc.ServicerContext) -> bool:
    code = getattr(context, "code", None)
    return callable(code) and code() not in (None, grpc.StatusCode.OK)


def _abort(context: grpc.ServicerContext, exc: Exception, method: str) -> None:
    if _already_aborted(context):
        raise exc
    if not context.is_active():
        # The caller cancelled or its deadline passed: there is no one to answer, and
        # aborting a finished call would only make grpcio log a traceback.
        log.debug("%s: the call had ended (%s: %s)", method, type(exc).__name__, exc)
        return
    code, message = status_for(exc, method)
    log.debug("%s -> %s: %s", method, code.name, message)
    if isinstance(exc, Overloaded) and exc.retry_after_ms is not None:
        context.set_trailing_metadata(((PUSHBACK_KEY, str(exc.retry_after_ms)),))
    context.abort(code, message)


Parse = Callable[[bytes], Any]


def _parser(deserializer: Parse | None) -> Parse:
    """The request deserializer, raising InvalidInput for bytes that are not the message:
    grpcio's own would answer INTERNAL and log a traceback for every such request."""
    if deserializer is None:
        return lambda data: data
    owner = getattr(deserializer, "__self__", None)
    name = getattr(getattr(owner, "DESCRIPTOR", None), "full_name", "request")

    def parse(data: bytes) -> Any:
        try:
            return deserializer(data)
        except Exception:
            raise InvalidInput(f"the request is not a valid {name} message "
                               f"({len(data):,} bytes)") from None

    return parse


def _none_is_nothing(serializer: Callable[[Any], bytes] | None
                     ) -> Callable[[Any], bytes] | None:
    """A call whose caller has gone ends with no answer (None, see _abort): grpcio would log
    a traceback trying to serialize it, once per late call of an overloaded service."""
    if serializer is None:
        return None
    return lambda message: b"" if message is None else serializer(message)


def _requests(stream: bool, parse: Parse, request: Any) -> Any:
    return (parse(item) for item in request) if stream else parse(request)


def _refuse(context: grpc.ServicerContext, limit: CallLimit,
            what: str = "calls in progress") -> None:
    wait_ms = limit.pushback_ms()
    context.set_trailing_metadata(((PUSHBACK_KEY, str(wait_ms)),))
    context.abort(grpc.StatusCode.RESOURCE_EXHAUSTED,
                  f"the service is busy ({limit.limit} {what}); retry in {wait_ms} ms")


def _wrap_unary_response(behavior: Callable[..., Any], method: str, parse: Parse,
                         stream: bool, limit: CallLimit | None) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Any:
        if limit is not None and not limit.try_enter():
            _refuse(context, limit)
        try:
            check_deadline(context)
            return behavior(_requests(stream, parse, request), context)
        except Exception as exc:
            _abort(context, exc, method)
        finally:
            if limit is not None:
                limit.leave()

    return handler


def _wrap_stream_response(behavior: Callable[..., Any], method: str, parse: Parse,
                          stream: bool, limit: CallLimit | None) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Iterator[Any]:
        if limit is not None and not limit.try_enter():
            _refuse(context, limit)
        try:
            check_deadline(context)
            yield from behavior(_requests(stream, parse, request), context)
        except Exception as exc:
            _abort(context, exc, method)
        finally:
            if limit is not None:
                limit.leave()

    return handler


def _wrap_message_stream(behavior: Callable[..., Any], method: str, parse: Parse,
                         limit: CallLimit | None, streams: OpenStreams) -> Callable[..., Any]:
    """A stream answered message by message (services/runtime/streams.py): one of `streams`
    while open, a call slot of `limit` (None: exempt) only while a message is answered."""
    def handler(request: Any, context: grpc.ServicerContext) -> Iterator[Any]:
        if not streams.open.try_enter():
            _refuse(context, streams.open, streams.what)
        received = idle_bounded(request, streams.idle_s, streams.key)
        admitted = per_message(received, parse, limit)
        try:
            check_deadline(context)
            yield from behavior(admitted, context)
        except Exception as exc:
            _abort(context, exc, method)
        finally:
            admitted.close()  # gives back the slot of a message whose answer was not asked for
            received.close()
            streams.open.leave()

    return handler


def streams_by_callback(handler: grpc.RpcMethodHandler) -> bool:
    """Whether a handler streams through a callback (grpcio's experimental_non_blocking, as
    grpc_health's Watch does) instead of holding one of the server's threads for as long as
    its stream is open."""
    return bool(getattr(handler.unary_stream, "experimental_non_blocking", False))


class ErrorMappingInterceptor(grpc.ServerInterceptor):
    """Error mapping and request parsing for every handler; the call limit for every handler
    but health and reflection, per message for the streams of `message_streams` (as many of
    them open at once as the limit allows calls). With `reflection_idle_s`, the exempt
    streams that wait for requests (reflection's) are bounded too: EXEMPT_STREAMS open at
    once, each closed after that long without a request."""

    def __init__(self, limit: CallLimit | None = None,
                 message_streams: MessageStreams | None = None,
                 reflection_idle_s: float | None = None) -> None:
        self.limit = limit
        self.message_streams: OpenStreams | None = None
        self.exempt_streams: OpenStreams | None = None
        self.stream_methods = message_streams.methods if message_streams else frozenset()
        if limit is None:
            return
        if message_streams is not None:
            self.message_streams = OpenStreams(
                CallLimit(limit.limit, limit.retry_after_ms), message_streams.idle_s,
                message_streams.key, "streams open")
        if reflection_idle_s is not None:
            self.exempt_streams = OpenStreams(
                CallLimit(EXEMPT_STREAMS, limit.retry_after_ms), reflection_idle_s,
                "server.reflection_idle_s", "reflection streams open")

    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        handler_call_details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        handler = continuation(handler_call_details)
        if handler is None:
            return None
        if streams_by_callback(handler):
            # Health's Watch, once per client that balances over replicas: a generator
            # wrapper would hold a thread per watcher until the pool had none left for calls.
            return handler
        method = handler_call_details.method
        limit = None if exempt(method) else self.limit
        parse = _parser(handler.request_deserializer)
        handler = handler._replace(request_deserializer=None,  # parsed in the wrappers
                                   response_serializer=_none_is_nothing(
                                       handler.response_serializer))
        if handler.unary_unary:
            return handler._replace(unary_unary=_wrap_unary_response(
                handler.unary_unary, method, parse, False, limit))
        if handler.stream_unary:
            return handler._replace(stream_unary=_wrap_unary_response(
                handler.stream_unary, method, parse, True, limit))
        if handler.unary_stream:
            return handler._replace(unary_stream=_wrap_stream_response(
                handler.unary_stream, method, parse, False, limit))
        if handler.stream_stream:
            return handler._replace(stream_stream=self._stream_stream(handler.stream_stream,
                                                                      method, parse, limit))
        return handler

    def _stream_stream(self, behavior: Callable[..., Any], method: str, parse: Parse,
                       limit: CallLimit | None) -> Callable[..., Any]:
        if self.message_streams is not None and method in self.stream_methods:
            return _wrap_message_stream(behavior, method, parse, limit, self.message_streams)
        if self.exempt_streams is not None and limit is None:
            # Exempt from the call limit, yet it holds a thread while it waits for the client.
            return _wrap_message_stream(behavior, method, parse, None, self.exempt_streams)
        return _wrap_stream_response(behavior, method, parse, True, limit)
