"""`oricf serve models`: declared models over the Open Inference Protocol, the real YOLOX-Nano
on real photos over a real channel; every bad request gets a clear status naming the tensor."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import grpc
import numpy as np
import pytest

from oricf.config import REPO_ROOT
from oricf.models.declaration import load_declaration
from oricf.models.heads import DetectionHead, declared_head
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.store import ModelStore
from tests.support.data import image
from tests.support.services import RunningService, running_service

YOLOX = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"


@pytest.fixture(scope="module")
def models_small_messages() -> Iterator[RunningService]:
    with running_service("models", {"server": {"max_message_mb": 8}}) as service:
        yield service


@pytest.fixture
def stub(models_small_messages: RunningService) -> oip_grpc.GRPCInferenceServiceStub:
    return oip_grpc.GRPCInferenceServiceStub(models_small_messages.channel)


@pytest.fixture(scope="module")
def head() -> DetectionHead:
    head = declared_head(load_declaration(YOLOX))
    assert isinstance(head, DetectionHead)
    return head


def persons(head: DetectionHead, outputs: dict[str, np.ndarray], file: str) -> int:
    prepared = head.prepare(cv2.imread(str(image(file))))
    found = head.decode(outputs, prepared, head.task.min_score)
    return sum(1 for c in found.class_ids if head.labels[c] == "person")


def test_server_and_model_readiness_and_metadata(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    assert stub.ServerLive(oip.ServerLiveRequest()).live
    assert stub.ServerReady(oip.ServerReadyRequest()).ready
    assert stub.ModelReady(oip.ModelReadyRequest(name="yolox-nano")).ready
    assert stub.ServerMetadata(oip.ServerMetadataRequest()).name == "oricf"
    meta = stub.ModelMetadata(oip.ModelMetadataRequest(name="yolox-nano"))
    assert meta.platform == "onnxruntime_onnx" and list(meta.versions) == ["1"]
    assert [(t.name, t.datatype, list(t.shape)) for t in meta.inputs] == [
        ("images", "FP32", [-1, 3, 416, 416])]  # declared free: a batch of any size
    assert [(t.name, t.datatype, list(t.shape)) for t in meta.outputs] == [
        ("output", "FP32", [-1, 3549, 85])]
    assert meta.properties["task"] == "detection"
    assert meta.properties["sha256"] == ModelStore().entry("yolox-nano").files[0].sha256


def test_model_infer_equals_onnxruntime_in_process(
        stub: oip_grpc.GRPCInferenceServiceStub, head: DetectionHead) -> None:
    import onnxruntime as ort

    prepared = head.prepare(cv2.imread(str(image("person.jpg"))))
    response = stub.ModelInfer(infer_request("yolox-nano", prepared.feeds, request_id="r1"))
    assert (response.model_name, response.model_version, response.id) == (
        "yolox-nano", "1", "r1")
    served = response_outputs(response)["output"]
    session = ort.InferenceSession(str(ModelStore().path("yolox-nano")))
    local = session.run(None, prepared.feeds)[0]
    np.testing.assert_allclose(served, local, rtol=1e-5, atol=1e-5)
    assert persons(head, {"output": served}, "person.jpg") == 1


def test_typed_contents_give_the_same_result_as_raw(
        stub: oip_grpc.GRPCInferenceServiceStub, head: DetectionHead) -> None:
    prepared = head.prepare(cv2.imread(str(image("person.jpg"))))
    tensor = prepared.feeds["images"]
    request = oip.ModelInferRequest(model_name="yolox-nano")
    request.inputs.add(name="images", datatype="FP32", shape=tensor.shape,
                       contents=oip.InferTensorContents(fp32_contents=tensor.reshape(-1)))
    typed = response_outputs(stub.ModelInfer(request))["output"]
    raw = response_outputs(stub.ModelInfer(infer_request("yolox-nano", prepared.feeds)))
    np.testing.assert_array_equal(typed, raw["output"])


@pytest.mark.parametrize(("file", "people"), [("person.jpg", 1), ("dog.jpg", 0),
                                              ("horses.jpg", 0)])
def test_an_encoded_image_is_pre_processed_by_the_server(
        stub: oip_grpc.GRPCInferenceServiceStub, head: DetectionHead, file: str,
        people: int) -> None:
    encoded = np.empty(1, dtype=object)
    encoded[0] = image(file).read_bytes()
    outputs = response_outputs(stub.ModelInfer(infer_request("yolox-nano",
                                                             {"images": encoded})))
    assert persons(head, outputs, file) == people


def test_only_the_requested_outputs_come_back(
        stub: oip_grpc.GRPCInferenceServiceStub, head: DetectionHead) -> None:
    prepared = head.prepare(cv2.imread(str(image("dog.jpg"))))
    response = stub.ModelInfer(infer_request("yolox-nano", prepared.feeds, outputs=["output"]))
    assert [o.name for o in response.outputs] == ["output"]


def _request(**changes: object) -> oip.ModelInferRequest:
    tensor = np.zeros((1, 3, 416, 416), np.float32)
    request = infer_request("yolox-nano", {"images": tensor})
    for key, value in changes.items():
        if key == "name":
            request.inputs[0].name = str(value)
        elif key == "datatype":
            request.inputs[0].datatype = str(value)
        elif key == "shape":
            del request.inputs[0].shape[:]
            request.inputs[0].shape.extend(value)  # type: ignore[arg-type]
        elif key == "raw":
            request.raw_input_contents[0] = value  # type: ignore[assignment]
        elif key == "output":
            request.outputs.add(name=str(value))
        else:
            setattr(request, key, value)
    return request


def _encoded(data: bytes) -> oip.ModelInferRequest:
    tensor = np.empty(1, dtype=object)
    tensor[0] = data
    return infer_request("yolox-nano", {"images": tensor})


def _bomb() -> bytes:
    """A real JPEG whose header says 30000x30000."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    at = data.index(b"\xff\xc0")
    data[at + 5:at + 9] = (30000).to_bytes(2, "big") * 2
    return bytes(data)


BAD = {
    "unknown model": (_request(model_name="nope"), grpc.StatusCode.NOT_FOUND, "no model 'nope'"),
    "unknown version": (_request(model_version="7"), grpc.StatusCode.NOT_FOUND,
                        "no version '7'"),
    "unknown input": (_request(name="pixels"), grpc.StatusCode.INVALID_ARGUMENT,
                      "no input 'pixels'"),
    "wrong shape": (_request(shape=[1, 3, 416, 200], raw=b"\0" * (3 * 416 * 200 * 4)),
                    grpc.StatusCode.INVALID_ARGUMENT, "input 'images': shape [1, 3, 416, 200]"),
    "wrong datatype": (_request(datatype="FP64", raw=b"\0" * (3 * 416 * 416 * 8)),
                       grpc.StatusCode.INVALID_ARGUMENT, "input 'images': datatype FP64"),
    "unknown datatype": (_request(datatype="FLOAT"), grpc.StatusCode.INVALID_ARGUMENT,
                         "unknown datatype 'FLOAT'"),
    "byte count": (_request(raw=b"\0" * 100), grpc.StatusCode.INVALID_ARGUMENT,
                   "tensor 'images': 100 bytes, but FP32 [1, 3, 416, 416] needs 2,076,672"),
    "negative dimension": (_request(shape=[1, -3, 416, 416]), grpc.StatusCode.INVALID_ARGUMENT,
                           "dimensions must be >= 0"),
    "unknown output": (_request(output="boxes"), grpc.StatusCode.INVALID_ARGUMENT,
                       "no output 'boxes'"),
    "missing input": (oip.ModelInferRequest(model_name="yolox-nano"),
                      grpc.StatusCode.INVALID_ARGUMENT, "input 'images' is missing"),
    "long name echoed short": (_request(name="x" * 100_000), grpc.StatusCode.INVALID_ARGUMENT,
                               "no input '" + "x" * 64 + "...'"),
    "not an image": (_encoded(b"GIF89a" + b"\0" * 100), grpc.StatusCode.INVALID_ARGUMENT,
                     "neither a JPEG nor a PNG"),
    "decompression bomb": (_encoded(_bomb()), grpc.StatusCode.INVALID_ARGUMENT,
                           "30000x30000 is over the limit"),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_requests_get_a_clear_status_and_the_server_goes_on(
        stub: oip_grpc.GRPCInferenceServiceStub, case: str) -> None:
    request, code, message = BAD[case]
    with pytest.raises(grpc.RpcError) as error:
        stub.ModelInfer(request, timeout=10)
    assert error.value.code() == code, error.value.details()
    assert message in (error.value.details() or "")
    assert stub.ServerReady(oip.ServerReadyRequest()).ready


def test_typed_contents_that_miscount_are_refused(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    request = oip.ModelInferRequest(model_name="yolox-nano")
    request.inputs.add(name="images", datatype="FP32", shape=[1, 3, 416, 416],
                       contents=oip.InferTensorContents(fp32_contents=[0.0] * 10))
    with pytest.raises(grpc.RpcError) as error:
        stub.ModelInfer(request)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "10 values in fp32_contents" in (error.value.details() or "")


def test_model_ready_and_metadata_of_unknown_models_are_not_found(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    for call, request in ((stub.ModelReady, oip.ModelReadyRequest(name="nope")),
                          (stub.ModelMetadata, oip.ModelMetadataRequest(name="nope"))):
        with pytest.raises(grpc.RpcError) as error:
            call(request)
        assert error.value.code() == grpc.StatusCode.NOT_FOUND


def test_not_ready_until_the_models_load() -> None:
    with running_service("models", load=False) as service:
        stub = oip_grpc.GRPCInferenceServiceStub(service.channel)
        assert stub.ServerLive(oip.ServerLiveRequest()).live
        assert not stub.ServerReady(oip.ServerReadyRequest()).ready
        assert not stub.ModelReady(oip.ModelReadyRequest(name="yolox-nano")).ready
        with pytest.raises(grpc.RpcError) as error:
            stub.ModelInfer(_request())
        assert error.value.code() == grpc.StatusCode.UNAVAILABLE


DECLARED = ["yolox-nano", "yolov8-fall", "text-direction"]


def _valid_input(stub: oip_grpc.GRPCInferenceServiceStub, model: str
                 ) -> tuple[str, np.ndarray]:
    """A zero tensor that fits the model's first input (a batch of 1; other free dimensions
    become 64)."""
    spec = stub.ModelMetadata(oip.ModelMetadataRequest(name=model)).inputs[0]
    assert spec.datatype == "FP32"
    batch, *rest = spec.shape
    return spec.name, np.zeros([batch if batch > 0 else 1, *(d if d > 0 else 64 for d in rest)],
                               np.float32)


@pytest.mark.parametrize("model", DECLARED)
def test_every_declared_model_is_served_and_refuses_bad_tensors(
        stub: oip_grpc.GRPCInferenceServiceStub, model: str) -> None:
    assert stub.ModelReady(oip.ModelReadyRequest(name=model)).ready
    name, tensor = _valid_input(stub, model)
    assert stub.ModelInfer(infer_request(model, {name: tensor})).outputs
    bad = {
        "unknown input": infer_request(model, {"nope": tensor}),
        "wrong datatype": infer_request(model, {name: tensor.astype(np.int32)}),
        "wrong rank": infer_request(model, {name: tensor[0]}),
        "byte count": infer_request(model, {name: tensor}),
    }
    bad["byte count"].raw_input_contents[0] = b"\0" * 12
    expected = {"unknown input": "no input 'nope'", "wrong datatype": "datatype INT32",
                "wrong rank": "shape", "byte count": "12 bytes"}
    for case, request in bad.items():
        with pytest.raises(grpc.RpcError) as error:
            stub.ModelInfer(request, timeout=10)
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT, case
        assert expected[case] in (error.value.details() or ""), case
    assert stub.ServerReady(oip.ServerReadyRequest()).ready


def test_an_oversized_request_is_refused_before_it_is_read(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    huge = infer_request("yolox-nano", {"images": np.zeros((6, 3, 416, 416), np.float32)})
    with pytest.raises(grpc.RpcError) as error:
        stub.ModelInfer(huge, timeout=10)
    assert error.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert stub.ServerReady(oip.ServerReadyRequest()).ready
