"""The policy service with a policy that sees (tests/support/camera_policy.py: the action is
the image's channel means, then the state): each declared camera's image, raw or encoded,
reaches the model as declared; a missing, unknown or broken image is INVALID_ARGUMENT and the
service goes on."""

from __future__ import annotations

import re
from collections.abc import Iterator

import cv2
import grpc
import numpy as np
import pytest

from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip_pb2
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc
from tests.support.camera_policy import CAMERA, committed_declaration
from tests.support.services import RunningService, running_service

STATE = [0.25, -1.5]


@pytest.fixture
def stub(camera_policy: RunningService) -> policy_pb2_grpc.PolicyStub:
    return policy_pb2_grpc.PolicyStub(camera_policy.channel)


def bgr(blue: int, green: int, red: int, size: tuple[int, int] = (48, 64)) -> np.ndarray:
    image = np.zeros((*size, 3), np.uint8)
    image[...] = (blue, green, red)
    return image


def observe(images: dict[str, common_pb2.Image], step: int = 3) -> policy_pb2.Observation:
    return policy_pb2.Observation(step=step, capture_time_ns=9, state=STATE, images=images)


def raw(image: np.ndarray) -> common_pb2.Image:
    return common_pb2.Image(data=image.tobytes(), encoding="bgr8", width=image.shape[1],
                            height=image.shape[0])


def encoded(image: np.ndarray, encoding: str) -> common_pb2.Image:
    ok, data = cv2.imencode(f".{encoding}", image)
    assert ok
    return common_pb2.Image(data=data.tobytes(), encoding=encoding)


@pytest.mark.parametrize("encoding", ["bgr8", "png", "jpeg"])
def test_each_cameras_image_reaches_the_model_in_the_declared_colour_order_and_scale(
        stub: policy_pb2_grpc.PolicyStub, encoding: str) -> None:
    red = bgr(0, 0, 255)
    image = raw(red) if encoding == "bgr8" else encoded(red, encoding)
    chunk = stub.Act(observe({CAMERA: image}), timeout=10)
    # rgb, 0-1: red is the first channel; the state follows unchanged
    np.testing.assert_allclose(chunk.actions, [1.0, 0.0, 0.0, *STATE], atol=0.02)
    assert (chunk.observation_step, chunk.capture_time_ns) == (3, 9)


def test_a_stream_of_images_is_answered_image_by_image(stub: policy_pb2_grpc.PolicyStub) -> None:
    colours = [bgr(255, 0, 0), bgr(0, 128, 0), bgr(0, 0, 0)]
    chunks = list(stub.ActStream(iter([observe({CAMERA: raw(c)}, step=i)
                                       for i, c in enumerate(colours)]), timeout=10))
    means = [list(np.round(c.actions[:3], 2)) for c in chunks]
    assert means == [[0.0, 0.0, 1.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.0]]


BAD = {
    "no image": ({}, "images: no image from camera top \\(policy channel-means sees top\\)"),
    "unknown camera": ({CAMERA: raw(bgr(0, 0, 0)), "wrist": raw(bgr(0, 0, 0))},
                       "images: policy channel-means has no camera 'wrist'"),
    "lying size": ({CAMERA: common_pb2.Image(data=bytes(30), encoding="bgr8", width=64,
                                             height=48)},
                   r"images: camera top: bgr8 image 64x48 needs 9,216 bytes \(64x48x3\), got 30"),
    "not a png": ({CAMERA: common_pb2.Image(data=b"\x89PNG\r\n\x1a\nxx", encoding="png")},
                  "images: camera top: PNG file without its IHDR header"),
    "unknown encoding": ({CAMERA: common_pb2.Image(data=b"x", encoding="yuv")},
                         "images: camera top: unknown image encoding"),
}


@pytest.mark.parametrize("case", BAD)
def test_a_missing_unknown_or_broken_image_is_invalid_argument(
        stub: policy_pb2_grpc.PolicyStub, case: str) -> None:
    images, message = BAD[case]
    with pytest.raises(grpc.RpcError) as err:
        stub.Act(observe(images), timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert re.search(message, err.value.details()), err.value.details()
    chunk = stub.Act(observe({CAMERA: raw(bgr(0, 0, 255))}), timeout=10)  # it goes on
    assert chunk.actions[0] == pytest.approx(1.0, abs=0.02)




@pytest.fixture
def oip(policy_models: RunningService) -> oip_grpc.GRPCInferenceServiceStub:
    """The same declaration in `oricf serve models`."""
    return oip_grpc.GRPCInferenceServiceStub(policy_models.channel)


def tensors(image: np.ndarray) -> oip_pb2.ModelInferRequest:
    return infer_request("channel-means", {"state": np.asarray([STATE], np.float32),
                                           "image": image})


def test_the_same_declaration_is_served_over_the_open_inference_protocol(
        oip: oip_grpc.GRPCInferenceServiceStub) -> None:
    image = np.zeros((1, 3, 8, 8), np.float32)
    image[0, 1] = 0.5  # raw tensors: the image as the model takes it
    outputs = response_outputs(oip.ModelInfer(tensors(image), timeout=10))
    np.testing.assert_allclose(outputs["action"][0], [0.0, 0.5, 0.0, *STATE], atol=1e-6)


def test_a_nan_image_over_the_open_inference_protocol_is_invalid_argument(
        oip: oip_grpc.GRPCInferenceServiceStub) -> None:
    image = np.zeros((1, 3, 8, 8), np.float32)
    image[0, 2, 3, 3] = np.nan
    with pytest.raises(grpc.RpcError) as err:
        oip.ModelInfer(tensors(image), timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "input 'image'[155] is nan: every value must be finite" in err.value.details()


@pytest.fixture(scope="module")
def committed_actions_policy(tmp_path_factory: pytest.TempPathFactory
                             ) -> Iterator[RunningService]:
    """`oricf serve policy` with a policy declared to take the committed actions."""
    folder = tmp_path_factory.mktemp("committed-actions-policy")
    with running_service("policy", {"model": str(committed_declaration(folder))}) as policy:
        yield policy


@pytest.mark.parametrize(("start", "expected"), [
    (3, [1.0 + 0.25, 1.0 - 1.5]),   # committed from the observation's step: its first row
    (4, [0.25, -1.5]),              # from the next step on: nothing for this one, zeros
    (None, [0.25, -1.5]),           # nothing committed
])
def test_a_policy_declared_to_take_the_committed_actions_is_fed_them_by_step(
        committed_actions_policy: RunningService, start: int | None,
        expected: list[float]) -> None:
    stub = policy_pb2_grpc.PolicyStub(committed_actions_policy.channel)
    request = policy_pb2.Observation(step=3, state=STATE)
    if start is not None:
        request.committed.start_step = start
        request.committed.actions.extend([1.0, 1.0, 2.0, 2.0])
    chunk = stub.Act(request, timeout=10)
    np.testing.assert_allclose(chunk.actions, expected, atol=1e-6)
