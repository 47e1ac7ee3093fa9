"""`oricf serve models` with fewer bytes each way: a UINT8 [H, W, C] image (rgb8, bgr8)
normalised on the server, and decoded detections instead of the output tensor, equal to
the detections in process; every misuse of either is INVALID_ARGUMENT naming it."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import grpc
import numpy as np
import pytest

from oricf.config import REPO_ROOT
from oricf.imaging import encode_image
from oricf.models.declaration import load_declaration
from oricf.models.declared import DeclaredModel
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.store import ModelStore
from tests.support.data import image
from tests.support.services import RunningService

YOLOX = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"
DECODED = {"output": {"decoded": True}}


@pytest.fixture(scope="module")
def stub(models: RunningService) -> oip_grpc.GRPCInferenceServiceStub:
    return oip_grpc.GRPCInferenceServiceStub(models.channel)


@pytest.fixture(scope="module")
def local() -> Iterator[DeclaredModel]:
    model = DeclaredModel(load_declaration(YOLOX), ModelStore())
    model.load()
    yield model
    model.close()


def ask(stub: oip_grpc.GRPCInferenceServiceStub, pixels: np.ndarray,
        outputs: dict[str, dict[str, object]], encoding: str | None = None
        ) -> tuple[np.ndarray, int]:
    parameters = {"images": {"encoding": encoding}} if encoding else {}
    response = stub.ModelInfer(infer_request("yolox-nano", {"images": pixels}, outputs,
                                             input_parameters=parameters), timeout=60)
    return response_outputs(response)["output"], response.ByteSize()


def test_uint8_pixels_and_decoded_detections_equal_those_in_process(
        stub: oip_grpc.GRPCInferenceServiceStub, local: DeclaredModel) -> None:
    bgr = cv2.imread(str(image("person.jpg")))
    expected = local.detect(local.prepare(bgr), 0.35)
    rows, size = ask(stub, bgr, DECODED, "bgr8")
    assert rows.shape == (len(expected.scores), 6) and len(rows) >= 1
    np.testing.assert_allclose(rows[:, :4], expected.boxes, atol=0.05)
    np.testing.assert_allclose(rows[:, 4], expected.scores, atol=1e-4)
    assert rows[:, 5].tolist() == expected.class_ids.tolist()
    assert size < 1000  # against 1.2 MB for the output tensor
    rgb_rows, _ = ask(stub, np.ascontiguousarray(bgr[:, :, ::-1]), DECODED)  # rgb8: default
    np.testing.assert_allclose(rgb_rows, rows, atol=1e-4)
    tensor, _ = ask(stub, bgr, {}, "bgr8")  # UINT8 in, the raw output tensor back
    assert tensor.shape == (1, 3549, 85)


def test_jpeg_in_decoded_out_keeps_only_the_asked_classes_and_scores(
        stub: oip_grpc.GRPCInferenceServiceStub) -> None:
    jpeg = np.empty(1, dtype=object)
    jpeg[0] = encode_image(cv2.imread(str(image("dog.jpg"))), "jpeg", 90)
    everything, _ = ask(stub, jpeg, DECODED)
    persons, _ = ask(stub, jpeg, {"output": {"decoded": True, "class_ids": "0"}})
    sure, _ = ask(stub, jpeg, {"output": {"decoded": True, "min_score": 0.9}})
    assert len(everything) >= 2 and set(everything[:, 5].tolist()) != {0.0}
    assert set(persons[:, 5].tolist()) <= {0.0}
    assert len(sure) < len(everything) and (sure[:, 4] >= 0.9).all()


@pytest.mark.parametrize(("pixels", "outputs", "encoding", "message"), [
    (np.zeros((1, 3, 416, 416), np.float32), DECODED, None, "send the image"),
    (np.zeros((48, 64, 3), np.uint8), {"output": {"decoded": True, "min_score": 2.0}}, None,
     "min_score"),
    (np.zeros((48, 64, 3), np.uint8), {"output": {"decoded": True, "class_ids": "0,x"}}, None,
     "class_ids"),
    (np.zeros((48, 64, 3), np.uint8), {"output": {"decoded": True, "class_ids": "80"}}, None,
     "class_ids"),
    (np.zeros((48, 64, 3), np.uint8), {}, "mono8", "encoding"),
    (np.zeros((48, 64, 3), np.uint8), {}, "yuv", "encoding"),
    (np.zeros((48, 64, 2), np.uint8), {}, None, "encoding"),
    (np.zeros((0, 64, 3), np.uint8), {}, None, "empty"),
])
def test_misused_images_and_decoding_are_invalid_argument(
        stub: oip_grpc.GRPCInferenceServiceStub, pixels: np.ndarray,
        outputs: dict[str, dict[str, object]], encoding: str | None, message: str) -> None:
    with pytest.raises(grpc.RpcError) as caught:
        ask(stub, pixels, outputs, encoding)
    assert caught.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert message in str(caught.value.details())
