"""The detector service: the real YOLOX-Nano on real photos and video, over a real channel."""

import queue
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from oricf.config import load_config
from oricf.errors import ConfigError
from oricf.services.detector.service import DetectorConfig
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image, video_frames
from tests.support.detections import count
from tests.support.services import RunningService


@pytest.fixture
def stub(detector: RunningService) -> detector_pb2_grpc.DetectorStub:
    return detector_pb2_grpc.DetectorStub(detector.channel)


def jpeg_request(file: str, **fields: object) -> detector_pb2.DetectRequest:
    data = image(file).read_bytes()
    return detector_pb2.DetectRequest(image=common_pb2.Image(data=data, encoding="jpeg"), **fields)


def raw_request(frame: np.ndarray, encoding: str = "bgr8", **fields: object
                ) -> detector_pb2.DetectRequest:
    pixels = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) if encoding == "rgb8" else frame
    height, width = frame.shape[:2]
    img = common_pb2.Image(data=pixels.tobytes(), encoding=encoding, width=width, height=height)
    return detector_pb2.DetectRequest(image=img, **fields)


def test_one_person_in_person_jpg(stub: detector_pb2_grpc.DetectorStub) -> None:
    response = stub.Detect(jpeg_request("person.jpg", labels=["person"]))
    assert count(response, "person") == 1
    (person,) = response.detections
    assert person.label == "person" and person.class_id == 0 and person.score > 0.5
    # The person stands in the right half of the 640x424 photo.
    assert 150 < person.box.x_min < person.box.x_max <= 640
    assert (response.image_width, response.image_height) == (640, 424)
    assert response.timings.inference_ms > 0 and response.timings.total_ms > 0


@pytest.mark.parametrize("file", ["dog.jpg", "horses.jpg"])
def test_no_people_in_animal_photos(stub: detector_pb2_grpc.DetectorStub, file: str) -> None:
    response = stub.Detect(jpeg_request(file, labels=["person"]))
    assert count(response, "person") == 0
    assert not response.detections


def test_all_labels_when_none_requested(stub: detector_pb2_grpc.DetectorStub) -> None:
    response = stub.Detect(jpeg_request("dog.jpg"))
    assert {"dog", "bicycle"} <= {d.label for d in response.detections}
    scores = [d.score for d in response.detections]
    assert scores == sorted(scores, reverse=True)


def test_plausible_counts_on_pedestrian_video(stub: detector_pb2_grpc.DetectorStub) -> None:
    counts = []
    for frame in video_frames([0, 150, 300, 450, 600]):
        response = stub.Detect(raw_request(frame, labels=["person"]))
        counts.append(count(response, "person"))
    # vtest.avi shows a street with a handful of pedestrians in every frame.
    assert all(2 <= c <= 12 for c in counts), counts


def test_raw_and_encoded_images_agree(stub: detector_pb2_grpc.DetectorStub) -> None:
    (frame,) = video_frames([0])
    ok, png = cv2.imencode(".png", frame)
    assert ok
    png_request = detector_pb2.DetectRequest(
        image=common_pb2.Image(data=png.tobytes(), encoding="png"), labels=["person"])
    results = [count(stub.Detect(r), "person")
               for r in (raw_request(frame, "bgr8", labels=["person"]),
                         raw_request(frame, "rgb8", labels=["person"]), png_request)]
    assert results[0] == results[1] == results[2] >= 2


def test_min_score_filters(stub: detector_pb2_grpc.DetectorStub) -> None:
    (frame,) = video_frames([300])
    loose = stub.Detect(raw_request(frame, labels=["person"], min_score=0.2))
    strict = stub.Detect(raw_request(frame, labels=["person"], min_score=0.7))
    assert count(loose, "person") > count(strict, "person")
    assert all(d.score >= 0.7 for d in strict.detections)


@pytest.mark.parametrize(("yaml", "key"), [
    ("detection: {label_map: {person: human}}", "detection.label_map"),
    ("images: {annotate_jpeg_quality: 85}", "images.annotate_jpeg_quality"),
    ("images: {default_annotate_encoding: png}", "images.default_annotate_encoding"),
])
def test_removed_post_processing_keys_are_refused_by_name(tmp_path: Path, yaml: str,
                                                          key: str) -> None:
    # Renaming labels and drawing boxes are the gateway's map_labels and annotate steps.
    config = tmp_path / "detector.yaml"
    config.write_text(yaml + "\n")
    with pytest.raises(ConfigError) as refused:
        load_config(config, DetectorConfig)
    assert str(refused.value) == f"{config}: {key}: unknown key"


def test_detect_stream_answers_every_frame_in_order(
        stub: detector_pb2_grpc.DetectorStub) -> None:
    frames = video_frames([0, 10, 20, 30, 40, 50])
    requests = (raw_request(f, labels=["person"], frame_id=i + 1) for i, f in enumerate(frames))
    responses = list(stub.DetectStream(requests))
    assert [r.frame_id for r in responses] == [1, 2, 3, 4, 5, 6]
    assert all(count(r, "person") >= 2 and not r.HasField("error") for r in responses)


def test_model_info(stub: detector_pb2_grpc.DetectorStub) -> None:
    info = stub.GetModelInfo(common_pb2.GetModelInfoRequest())
    assert info.service == "detector" and info.model == "yolox-nano"
    assert info.runtime.startswith("onnxruntime ")
    assert "CPUExecutionProvider" in info.providers
    assert len(info.labels) == 80 and info.labels[0] == "person"
    assert info.sha256.startswith("615e2661") and info.license.startswith("Apache-2.0")
    assert info.load_seconds > 0


def test_detect_stream_answers_each_frame_before_the_next_arrives(
        stub: detector_pb2_grpc.DetectorStub) -> None:
    # A camera sends one frame at a time: each answer must come without waiting for the next.
    outgoing: queue.Queue[detector_pb2.DetectRequest | None] = queue.Queue()
    responses = stub.DetectStream(iter(outgoing.get, None), timeout=30)
    for frame_id, frame in enumerate(video_frames([0, 50, 100]), start=1):
        outgoing.put(raw_request(frame, labels=["person"], frame_id=frame_id))
        assert next(responses).frame_id == frame_id
    outgoing.put(None)
    assert list(responses) == []


def test_cancelled_stream_leaves_no_reader_behind(stub: detector_pb2_grpc.DetectorStub) -> None:
    outgoing: queue.Queue[detector_pb2.DetectRequest | None] = queue.Queue()
    responses = stub.DetectStream(iter(outgoing.get, None), timeout=30)
    (frame,) = video_frames([0])
    outgoing.put(raw_request(frame, labels=["person"], frame_id=1))
    assert next(responses).frame_id == 1
    responses.cancel()
    outgoing.put(None)
    deadline = time.monotonic() + 5
    while any(t.name == "detect-stream-reader" for t in threading.enumerate()):
        assert time.monotonic() < deadline, "the stream's reader thread is still running"
        time.sleep(0.05)
    assert count(stub.Detect(raw_request(frame, labels=["person"]), timeout=10), "person") >= 2
