"""Bytes that are not the request message get INVALID_ARGUMENT (not grpcio's INTERNAL with a
traceback per request), on every RPC; a huge echoed value still gets INVALID_ARGUMENT."""

from __future__ import annotations

import logging

import grpc
import pytest

from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image
from tests.support.services import RunningService

# Field 1 as a length-delimited value that runs past the end: no message parses this.
GARBAGE = b"\x0a\xff\xff\xff\x0f" + b"\x00" * 20

RPCS = {
    "detector": [("/oricf.v1.Detector/Detect", "unary"),
                 ("/oricf.v1.Detector/DetectStream", "stream"),
                 ("/oricf.v1.Detector/GetModelInfo", "unary"),
                 ("/grpc.health.v1.Health/Check", "unary")],
    "models": [(f"/inference.GRPCInferenceService/{name}", "unary") for name in (
        "ServerLive", "ServerReady", "ModelReady", "ServerMetadata", "ModelMetadata",
        "ModelInfer")],
}


@pytest.fixture(scope="module", params=list(RPCS))
def service(request: pytest.FixtureRequest) -> tuple[str, RunningService]:
    """Each service of RPCS: the session's, with its shipped settings."""
    return request.param, request.getfixturevalue(request.param)


def test_undecodable_requests_are_invalid_argument_on_every_rpc(
        service: tuple[str, RunningService], caplog: pytest.LogCaptureFixture) -> None:
    name, running = service
    caplog.set_level(logging.DEBUG)
    for method, kind in RPCS[name]:
        if kind == "unary":
            call = running.channel.unary_unary(method)
            with pytest.raises(grpc.RpcError) as error:
                call(GARBAGE, timeout=10)
        else:
            stream = running.channel.stream_stream(method)
            with pytest.raises(grpc.RpcError) as error:
                list(stream(iter([GARBAGE]), timeout=10))
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT, method
        assert "is not a valid" in (error.value.details() or ""), method
    assert not [r for r in caplog.records if r.exc_info or "Traceback" in r.getMessage()]


def test_a_huge_echoed_label_is_cut_and_still_invalid_argument(detector: RunningService) -> None:
    stub = detector_pb2_grpc.DetectorStub(detector.channel)
    request = detector_pb2.DetectRequest(
        image=common_pb2.Image(data=image("person.jpg").read_bytes(), encoding="jpeg"),
        labels=["x" * 1_000_000])
    with pytest.raises(grpc.RpcError) as error:
        stub.Detect(request, timeout=10)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    details = error.value.details() or ""
    assert details.startswith("unknown label 'xxx") and details.endswith("... (cut)")
    assert len(details) < 1100
