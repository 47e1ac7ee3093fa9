"""Shapes no model can run on (an empty tensor, more dimensions than an array can have), raw
or typed, get INVALID_ARGUMENT naming the input, with one log line and no traceback."""

from __future__ import annotations

import logging

import grpc
import numpy as np
import pytest

from oricf.models.wire import infer_request
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from tests.support.services import RunningService


@pytest.fixture(scope="module")
def stub(models: RunningService) -> oip_grpc.GRPCInferenceServiceStub:
    return oip_grpc.GRPCInferenceServiceStub(models.channel)


def raw(model: str, name: str, shape: list[int], data: bytes) -> oip.ModelInferRequest:
    request = infer_request(model, {name: np.zeros(1, np.float32)})
    del request.inputs[0].shape[:]
    request.inputs[0].shape.extend(shape)
    request.raw_input_contents[0] = data
    return request


def typed(model: str, name: str, shape: list[int], values: list[float]
          ) -> oip.ModelInferRequest:
    request = oip.ModelInferRequest(model_name=model)
    request.inputs.add(name=name, datatype="FP32", shape=shape,
                       contents=oip.InferTensorContents(fp32_contents=values))
    return request


DEEP = [1] * 65
CASES = {
    "empty batch, yolox-nano": (raw("yolox-nano", "images", [0, 3, 416, 416], b""),
                                "input 'images': shape [0, 3, 416, 416]: dimensions must be > 0"),
    "empty width, text-direction": (raw("text-direction", "x", [1, 3, 48, 0], b""),
                                    "dimensions must be > 0"),
    "empty, typed": (typed("yolox-nano", "images", [0, 3, 416, 416], []),
                     "dimensions must be > 0"),
    "65 dimensions, raw": (raw("yolox-nano", "images", DEEP, b"\0" * 4),
                           "input 'images': 65 dimensions; at most 64"),
    "65 dimensions, typed": (typed("yolox-nano", "images", DEEP, [0.0]),
                             "input 'images': 65 dimensions; at most 64"),
    "1000 dimensions, typed": (typed("text-direction", "x", [1] * 1000, [0.0]),
                               "1000 dimensions; at most 64"),
}


@pytest.mark.parametrize("case", CASES)
def test_shapes_no_model_runs_on_are_invalid_argument_without_a_traceback(
        stub: oip_grpc.GRPCInferenceServiceStub, case: str,
        caplog: pytest.LogCaptureFixture) -> None:
    request, message = CASES[case]
    with caplog.at_level(logging.DEBUG, logger="oricf"), pytest.raises(grpc.RpcError) as error:
        stub.ModelInfer(request, timeout=10)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT, error.value.details()
    assert message in (error.value.details() or "")
    service_lines = [r for r in caplog.records if r.name.startswith("oricf.services")]
    assert len(service_lines) == 1 and service_lines[0].levelno == logging.DEBUG
    assert service_lines[0].exc_info is None
    assert stub.ServerReady(oip.ServerReadyRequest()).ready
