"""Every bad input gets a clear status, and the service keeps serving afterwards."""

from collections.abc import Iterator

import grpc
import pytest

from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image
from tests.support.detections import count
from tests.support.services import RunningService, running_service


@pytest.fixture(scope="module")
def detector_small_messages() -> Iterator[RunningService]:
    # A small message limit so that "over the limit" needs only a few megabytes.
    with running_service("detector", {"server": {"max_message_mb": 2}}) as service:
        yield service


@pytest.fixture
def stub(detector_small_messages: RunningService) -> detector_pb2_grpc.DetectorStub:
    return detector_pb2_grpc.DetectorStub(detector_small_messages.channel)


def good_request() -> detector_pb2.DetectRequest:
    data = image("person.jpg").read_bytes()
    return detector_pb2.DetectRequest(image=common_pb2.Image(data=data, encoding="jpeg"),
                                      labels=["person"])


def raw(data: bytes, encoding: str, width: int, height: int, **fields: object
        ) -> detector_pb2.DetectRequest:
    img = common_pb2.Image(data=data, encoding=encoding, width=width, height=height)
    return detector_pb2.DetectRequest(image=img, **fields)


BAD_REQUESTS = {
    "empty data": (raw(b"", "jpeg", 0, 0), "image data is empty"),
    "undecodable jpeg": (raw(b"\xff\xd8\xff\xe0" + b"x" * 500, "jpeg", 0, 0),
                         "corrupt or truncated"),
    "wrong raw length": (raw(b"\x00" * 1000, "rgb8", 640, 480),
                         "rgb8 image 640x480 needs 921,600 bytes"),
    "unknown encoding": (raw(b"\x00" * 12, "yuyv", 2, 2), "unknown image encoding 'yuyv'"),
    "zero size": (raw(b"\x00" * 12, "bgr8", 0, 4), "width and height must be > 0"),
    "absurd size": (raw(b"\x00" * 12, "bgr8", 200_000, 200_000), "over the limit"),
    "unknown label": (raw(b"\x00" * 12, "bgr8", 2, 2, labels=["persn"]),
                      "unknown label 'persn' (did you mean 'person'?)"),
    "min_score out of range": (raw(b"\x00" * 12, "bgr8", 2, 2, min_score=1.5),
                               "min_score 1.5 is out of range"),
}


@pytest.mark.parametrize("case", BAD_REQUESTS)
def test_bad_input_is_invalid_argument_and_service_goes_on(
        stub: detector_pb2_grpc.DetectorStub, case: str) -> None:
    request, message = BAD_REQUESTS[case]
    with pytest.raises(grpc.RpcError) as err:
        stub.Detect(request, timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert message in err.value.details()
    assert count(stub.Detect(good_request(), timeout=10), "person") == 1


def test_message_over_the_limit_is_resource_exhausted(
        stub: detector_pb2_grpc.DetectorStub) -> None:
    width, height = 1920, 1080  # 6.2 MB raw: over the 2 MB limit of this service
    with pytest.raises(grpc.RpcError) as err:
        stub.Detect(raw(b"\x00" * (width * height * 3), "rgb8", width, height), timeout=10)
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert count(stub.Detect(good_request(), timeout=10), "person") == 1


def test_bad_frame_in_a_stream_does_not_end_it(stub: detector_pb2_grpc.DetectorStub) -> None:
    frames = [good_request(), raw(b"\x00" * 5, "rgb8", 2, 2), good_request()]
    for frame_id, frame in enumerate(frames, start=1):
        frame.frame_id = frame_id
    responses = list(stub.DetectStream(iter(frames), timeout=20))
    assert [r.frame_id for r in responses] == [1, 2, 3]
    assert responses[1].error.code == grpc.StatusCode.INVALID_ARGUMENT.value[0]
    assert "needs 12 bytes" in responses[1].error.message
    assert count(responses[0], "person") == count(responses[2], "person") == 1


def test_expired_deadline_is_deadline_exceeded(stub: detector_pb2_grpc.DetectorStub) -> None:
    with pytest.raises(grpc.RpcError) as err:
        stub.Detect(good_request(), timeout=0.0001)
    assert err.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    assert count(stub.Detect(good_request(), timeout=10), "person") == 1
