"""Domain errors map to status codes in one place; unexpected errors leak nothing.

A real gRPC server with a generic handler stands in for a model here: the point is the
runtime's mapping, which every service shares, including errors no real model raises on cue.
"""

from collections.abc import Iterator
from concurrent import futures

import grpc
import pytest

from oricf.errors import InvalidInput, NotReady, Overloaded
from oricf.services.runtime.errors import INTERNAL_MESSAGE, ErrorMappingInterceptor

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
