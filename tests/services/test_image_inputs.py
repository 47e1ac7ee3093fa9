"""Images as cameras and phones write them, and as attackers do, sent to the detector's
Detect and to an image input of the models service's ModelInfer: EXIF orientation, repeated
progressive scans, and decoding that outlasts the caller's deadline."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import cv2
import grpc
import numpy as np
import pytest

from oricf.config import REPO_ROOT
from oricf.models.declaration import load_declaration
from oricf.models.heads import DetectionHead, declared_head
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image
from tests.support.detections import count
from tests.support.jpegs import progressive, slow_to_decode, with_orientation, with_repeated_scans
from tests.support.services import RunningService

PERSON = image("person.jpg")  # 640x424, one person


def person_pixels() -> np.ndarray:
    pixels = cv2.imread(str(PERSON))
    assert pixels is not None
    return pixels


def detect(service: RunningService, data: bytes, timeout: float = 30
           ) -> detector_pb2.DetectResponse:
    request = detector_pb2.DetectRequest(image=common_pb2.Image(data=data, encoding="jpeg"),
                                         labels=["person"])
    return detector_pb2_grpc.DetectorStub(service.channel).Detect(request, timeout=timeout)


def infer(service: RunningService, data: bytes, timeout: float = 30) -> dict[str, np.ndarray]:
    tensor = np.empty(1, dtype=object)
    tensor[0] = data
    stub = oip_grpc.GRPCInferenceServiceStub(service.channel)
    return response_outputs(stub.ModelInfer(infer_request("yolox-nano", {"images": tensor}),
                                            timeout=timeout))


def infer_persons(service: RunningService, data: bytes) -> int:
    head = declared_head(load_declaration(REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"))
    assert isinstance(head, DetectionHead)
    stored = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_IGNORE_ORIENTATION
                          | cv2.IMREAD_COLOR)
    assert stored is not None
    found = head.decode(infer(service, data), head.prepare(stored), head.task.min_score)
    return sum(1 for c in found.class_ids if head.labels[c] == "person")


def test_a_photo_with_exif_orientation_is_detected_in_its_stored_grid(
        detector: RunningService) -> None:
    rotated = with_orientation(PERSON.read_bytes(), 6)  # phones write this when held upright
    response = detect(detector, rotated)
    assert (response.image_width, response.image_height) == (640, 424)  # not turned
    assert count(response, "person") == 1
    plain = detect(detector, PERSON.read_bytes())
    assert [d.box for d in response.detections] == [d.box for d in plain.detections]


def test_a_photo_with_exif_orientation_is_inferred(models: RunningService) -> None:
    assert infer_persons(models, with_orientation(PERSON.read_bytes(), 6)) == 1


def test_a_real_progressive_jpeg_is_served(detector: RunningService,
                                           models: RunningService) -> None:
    data = progressive(person_pixels())
    assert count(detect(detector, data), "person") == 1
    assert infer_persons(models, data) == 1


def repeated_scans() -> bytes:
    return with_repeated_scans(progressive(person_pixels()), 200)


@pytest.mark.parametrize("call", [detect, infer], ids=["Detect", "ModelInfer"])
def test_a_jpeg_with_repeated_scans_is_refused_before_decoding(
        detector: RunningService, models: RunningService,
        call: Callable[[RunningService, bytes], Any]) -> None:
    service = detector if call is detect else models
    with pytest.raises(grpc.RpcError) as error:
        call(service, repeated_scans())
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "more than 64 scans" in (error.value.details() or "")
    assert count(detect(detector, PERSON.read_bytes()), "person") == 1


def _idle(service: RunningService) -> None:
    """Waits until the service has finished every call (its handlers go on after a caller
    gave up)."""
    give_up = time.monotonic() + 60
    while service.host.call_limit.active and time.monotonic() < give_up:
        time.sleep(0.05)
    assert service.host.call_limit.active == 0


@pytest.mark.parametrize("rpc", ["Detect", "ModelInfer"])
def test_no_inference_runs_once_decoding_took_the_whole_deadline(
        detector: RunningService, models: RunningService, rpc: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    service = detector if rpc == "Detect" else models
    model = service.host.slot.peek()
    model = model.model if rpc == "Detect" else model.get("yolox-nano")
    method = "detect" if rpc == "Detect" else "infer"
    ran: list[str] = []
    real = getattr(model, method)

    def counted(*args: Any) -> Any:
        ran.append(method)
        return real(*args)

    monkeypatch.setattr(model, method, counted)
    data = slow_to_decode()  # within every limit; decoding it takes longer than 0.2 s
    with pytest.raises(grpc.RpcError) as error:
        (detect if rpc == "Detect" else infer)(service, data, timeout=0.2)
    assert error.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    _idle(service)
    assert ran == []
    (detect if rpc == "Detect" else infer)(service, PERSON.read_bytes())
    assert ran == [method]
