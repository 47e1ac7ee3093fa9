"""Domain errors map to status codes in one place; unexpected errors leak nothing.

A real gRPC server with a generic handler stands in for a model here: the point is the
runtime's mapping, which every service shares, including errors no real model raises on cue.
"""

import logging
import time
from collections.abc import Iterator
from concurrent import futures

import grpc
import pytest

from oricf.errors import InvalidInput, NotReady, Overloaded
from oricf.services.runtime.errors import INTERNAL_MESSAGE, ErrorMappingInterceptor
from oricf.v1 import common_pb2

ERRORS = {
    "invalid": (InvalidInput("bad image"), grpc.StatusCode.INVALID_ARGUMENT, "bad image"),
    "loading": (NotReady("loading"), grpc.StatusCode.UNAVAILABLE, "loading"),
    "busy": (Overloaded("queue full"), grpc.StatusCode.RESOURCE_EXHAUSTED, "queue full"),
    "bug": (KeyError("/secret/path"), grpc.StatusCode.INTERNAL, INTERNAL_MESSAGE),
}


def _raise(request: bytes, context: grpc.ServicerContext) -> bytes:
    raise ERRORS[request.decode()][0]


def _stream_then_raise(request: bytes, context: grpc.ServicerContext) -> Iterator[bytes]:
    yield b"first"
    raise ERRORS[request.decode()][0]


@pytest.fixture(scope="module")
def channel() -> Iterator[grpc.Channel]:
    server = grpc.server(futures.ThreadPoolExecutor(4), interceptors=[ErrorMappingInterceptor()])
    handler = grpc.method_handlers_generic_handler("test.Errors", {
        "Unary": grpc.unary_unary_rpc_method_handler(_raise),
        "Stream": grpc.unary_stream_rpc_method_handler(_stream_then_raise),
    })
    server.add_generic_rpc_handlers((handler,))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    with grpc.insecure_channel(f"127.0.0.1:{port}") as ch:
        yield ch
    server.stop(0)


@pytest.mark.parametrize("case", ERRORS)
def test_unary_errors_map_to_status_codes(channel: grpc.Channel, case: str) -> None:
    call = channel.unary_unary("/test.Errors/Unary")
    with pytest.raises(grpc.RpcError) as err:
        call(case.encode(), timeout=5)
    _, code, message = ERRORS[case]
    assert err.value.code() == code
    assert err.value.details() == message
    assert "secret" not in (err.value.details() or "")


@pytest.mark.parametrize("case", ERRORS)
def test_stream_errors_map_to_status_codes(channel: grpc.Channel, case: str) -> None:
    call = channel.unary_stream("/test.Errors/Stream")
    stream = call(case.encode(), timeout=5)
    assert next(stream) == b"first"
    with pytest.raises(grpc.RpcError) as err:
        next(stream)
    assert err.value.code() == ERRORS[case][1]


def _answer_after_the_caller_left(request: bytes, context: grpc.ServicerContext
                                  ) -> common_pb2.GetModelInfoResponse:
    if request == b"now":
        return common_pb2.GetModelInfoResponse(service="ok")
    deadline = time.monotonic() + 10
    while context.is_active() and time.monotonic() < deadline:  # until the caller is gone
        time.sleep(0.01)
    raise Overloaded("too late")


def test_a_call_whose_caller_left_ends_without_a_traceback(
        caplog: pytest.LogCaptureFixture) -> None:
    # One worker: the second call runs once the first one's handler, and the sending of
    # its (absent) answer, are over.
    server = grpc.server(futures.ThreadPoolExecutor(1), interceptors=[ErrorMappingInterceptor()])
    server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler("test.Late", {
        "Unary": grpc.unary_unary_rpc_method_handler(
            _answer_after_the_caller_left,
            response_serializer=common_pb2.GetModelInfoResponse.SerializeToString)}),))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel, \
                caplog.at_level(logging.DEBUG, logger="grpc"):
            call = channel.unary_unary("/test.Late/Unary")
            with pytest.raises(grpc.RpcError) as late:
                call(b"late", timeout=0.2)
            assert late.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
            answer = common_pb2.GetModelInfoResponse.FromString(call(b"now", timeout=10))
            assert answer.service == "ok"
    finally:
        server.stop(0)
    logged = [r.getMessage() for r in caplog.records if r.name.startswith("grpc")]
    assert not [m for m in logged if "Exception" in m], logged
