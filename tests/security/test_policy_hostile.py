"""The Policy service against hostile clients, over a real channel: a stream that goes quiet
is closed after `stream_idle_s` and gives back everything it held; camera images that would
cost far more decoded than sent (a 116 KB PNG of 6300x6300 for an 8x8 input, a few hundred
bytes of JPEG claiming 6000x6000, a truncated JPEG) are INVALID_ARGUMENT before anything
large is allocated, and an image beyond the memory budget (`server.max_inflight_mb`) is
refused as the detector refuses it. Reflection streams, which every service serves outside
its call limit, are bounded on their own and closed after `server.reflection_idle_s`, so
quiet ones leave the service's threads to calls and health checks. The service is SERVING
afterwards."""

from __future__ import annotations

import re
import struct
import threading
import zlib
from collections.abc import Iterator
from concurrent import futures
from contextlib import contextmanager
from typing import Any

import cv2
import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc

from oricf.services.runtime.limits import EXEMPT_STREAMS
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc
from tests.support.camera_policy import CAMERA, declaration
from tests.support.jpegs import claiming
from tests.support.peak_memory import peak_growth
from tests.support.services import RunningService, running_service
from tests.support.waiting import wait_for

IDLE_S = 0.5
BUDGET_MB = 8  # a 1920x1080 image needs 12 MB to decode: within the pixel limit, not this
STATE = [0.25, -1.5]
CALLS = 8  # at once: the service's call limit
# Eight 6300x6300 images decoded at once would hold about 1 GB; refused on their headers,
# what is left is the messages and the allocator's slack.
MAX_GROWTH_MB = 100
# More quiet reflection streams than the service has threads (2 x CALLS + 4).
QUIET_STREAMS = 3 * CALLS


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningService]:
    folder = tmp_path_factory.mktemp("camera-policy")
    overrides = {"model": str(declaration(folder)), "stream_idle_s": IDLE_S,
                 "server": {"max_inflight_mb": BUDGET_MB, "reflection_idle_s": IDLE_S}}
    with running_service("policy", overrides) as running:
        yield running
        health = health_pb2_grpc.HealthStub(running.channel).Check(
            health_pb2.HealthCheckRequest(), timeout=10)
        assert health.status == health_pb2.HealthCheckResponse.SERVING


@pytest.fixture
def stub(service: RunningService) -> policy_pb2_grpc.PolicyStub:
    return policy_pb2_grpc.PolicyStub(service.channel)


def observe(image: common_pb2.Image, step: int = 1) -> policy_pb2.Observation:
    return policy_pb2.Observation(step=step, state=STATE, images={CAMERA: image})


def good() -> common_pb2.Image:
    pixels = np.zeros((48, 64, 3), np.uint8)
    return common_pb2.Image(data=pixels.tobytes(), encoding="bgr8", width=64, height=48)


def blank_png(width: int, height: int) -> bytes:
    """A valid black RGB PNG of width x height, compressed row by row: a few hundred
    kilobytes made without ever holding the image."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    deflate = zlib.compressobj(9)
    row = bytes(1 + 3 * width)  # filter byte 0, then black pixels
    body = b"".join(deflate.compress(row) for _ in range(height)) + deflate.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", body)
            + chunk(b"IEND", b""))


def refusal(stub: policy_pb2_grpc.PolicyStub, image: common_pb2.Image) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as err:
        stub.Act(observe(image), timeout=30)
    return err.value


def test_a_quiet_stream_is_closed_after_stream_idle_s_and_holds_nothing(
        service: RunningService, stub: policy_pb2_grpc.PolicyStub) -> None:
    released = threading.Event()

    def one_then_quiet() -> Iterator[policy_pb2.Observation]:
        yield observe(good())
        released.wait(timeout=30)  # a client that never sends again nor closes

    stream = stub.ActStream(one_then_quiet(), timeout=30)
    try:
        assert not next(stream).HasField("error")
        with pytest.raises(grpc.RpcError) as err:
            next(stream)
    finally:
        released.set()
    assert err.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    assert f"nothing was sent for {IDLE_S:g} s; the stream is closed (stream_idle_s)" \
        in err.value.details()
    wait_for(lambda: service.host.call_limit.active == 0, 10, "the call slot given back")
    wait_for(lambda: not [t for t in threading.enumerate() if t.name == "stream-reader"], 10,
             "the stream's reader thread ended")
    assert stub.Act(observe(good()), timeout=10).actions  # it goes on


def test_huge_pngs_are_refused_on_their_headers_and_peak_memory_stays_bounded(
        stub: policy_pb2_grpc.PolicyStub) -> None:
    data = blank_png(6300, 6300)  # 116 KB; 119 MB decoded, under the 40 MP of any image
    assert len(data) < 200_000
    image = common_pb2.Image(data=data, encoding="png")
    with peak_growth() as growth:
        calls = [stub.Act.future(observe(image), timeout=60) for _ in range(CALLS)]
        codes = [call.code() for call in calls]
    assert growth() < MAX_GROWTH_MB * 2**20, f"peak memory grew {growth() / 2**20:.0f} MB"
    assert codes == [grpc.StatusCode.INVALID_ARGUMENT] * CALLS, codes
    assert "images: camera top: image size 6300x6300 is over the limit of 2,073,600 pixels" \
        in calls[0].details()


def test_a_corrupt_truncated_or_lying_jpeg_is_invalid_argument(
        stub: policy_pb2_grpc.PolicyStub) -> None:
    noise = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    jpeg = cv2.imencode(".jpg", noise)[1].tobytes()
    cases = {
        "claims 6000x6000": (claiming(6000, 6000), "image size 6000x6000 is over the limit"),
        "claims 640x480": (claiming(640, 480), "too few for the 640x480 image its frame header"),
        "truncated": (jpeg[:len(jpeg) // 2], "not a valid JPEG file"),
        "no image data": (jpeg[:200], "JPEG"),
    }
    for case, (data, message) in cases.items():
        error = refusal(stub, common_pb2.Image(data=data, encoding="jpeg"))
        assert error.code() == grpc.StatusCode.INVALID_ARGUMENT, case
        assert re.search(message, error.details()), (case, error.details())
    assert stub.Act(observe(good()), timeout=10).actions


def test_an_image_beyond_the_memory_budget_is_refused_alone(
        stub: policy_pb2_grpc.PolicyStub) -> None:
    big = common_pb2.Image(data=blank_png(1920, 1080), encoding="png")  # 12 MB to decode
    error = refusal(stub, big)
    assert error.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert f"a 1920x1080 image: about 12 MB to hold while it runs, more than the service's " \
           f"whole budget for data in flight ({BUDGET_MB} MB)" in error.details()
    chunks = list(stub.ActStream(iter([observe(good(), 1), observe(big, 2),
                                       observe(good(), 3)]), timeout=30))
    assert [(c.observation_step, c.HasField("error")) for c in chunks] == [
        (1, False), (2, True), (3, False)]


@contextmanager
def quiet_reflection_streams(address: str, count: int
                             ) -> Iterator[tuple[grpc.Channel, list[Iterator[Any]]]]:
    """`count` reflection streams on a channel of their own, each asking once and then
    neither asking again nor closing; closed on exit, once the service has let them go."""
    released = threading.Event()

    def ask_once_then_quiet() -> Iterator[reflection_pb2.ServerReflectionRequest]:
        yield reflection_pb2.ServerReflectionRequest(list_services="")
        released.wait(timeout=30)

    channel = grpc.insecure_channel(address)
    stub = reflection_pb2_grpc.ServerReflectionStub(channel)
    try:
        yield channel, [stub.ServerReflectionInfo(ask_once_then_quiet(), timeout=30)
                        for _ in range(count)]
    finally:
        released.set()
        channel.close()  # ends the streams still open
    wait_for(lambda: not [t for t in threading.enumerate() if t.name == "stream-reader"], 10,
             "the streams' reader threads ended")


def first_answer(stream: Iterator[Any]) -> grpc.StatusCode | None:
    """None when the stream answered its request, else the code it ended with."""
    try:
        next(stream)
        return None
    except grpc.RpcError as exc:
        return exc.code()


def test_quiet_reflection_streams_leave_the_threads_to_calls_and_health(
        service: RunningService, stub: policy_pb2_grpc.PolicyStub) -> None:
    # The streams close first on the way out, so that no reader waits on one.
    with futures.ThreadPoolExecutor(QUIET_STREAMS) as readers, \
            quiet_reflection_streams(service.address, QUIET_STREAMS) as (_, streams):
        answers = [readers.submit(first_answer, stream) for stream in streams]
        # Each is answered or refused at once; one past the bound would hold a thread.
        futures.wait(answers, timeout=10)
        assert stub.Act(observe(good()), timeout=5).actions
        health = health_pb2_grpc.HealthStub(service.channel).Check(
            health_pb2.HealthCheckRequest(), timeout=5)
        assert health.status == health_pb2.HealthCheckResponse.SERVING
        codes = [answer.result(timeout=10) for answer in answers]
        assert codes.count(None) == EXEMPT_STREAMS, codes
        assert codes.count(grpc.StatusCode.RESOURCE_EXHAUSTED) == QUIET_STREAMS - EXEMPT_STREAMS
        refused = next(s for s, code in zip(streams, codes, strict=True) if code is not None)
        assert f"the service is busy ({EXEMPT_STREAMS} reflection streams open)" \
            in refused.details()  # type: ignore[attr-defined]


def test_a_quiet_reflection_stream_is_closed_after_reflection_idle_s(
        service: RunningService) -> None:
    with quiet_reflection_streams(service.address, EXEMPT_STREAMS) as (channel, streams):
        assert [first_answer(stream) for stream in streams] == [None] * EXEMPT_STREAMS
        for stream in streams:
            with pytest.raises(grpc.RpcError) as err:
                next(stream)
            assert err.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
            assert f"nothing was sent for {IDLE_S:g} s; the stream is closed " \
                   f"(server.reflection_idle_s)" in err.value.details()
        # Their places are free again: a whole reflection exchange is answered.
        stub = reflection_pb2_grpc.ServerReflectionStub(channel)
        request = reflection_pb2.ServerReflectionRequest(list_services="")
        (reply,) = stub.ServerReflectionInfo(iter([request]), timeout=10)
        names = {s.name for s in reply.list_services_response.service}
        assert "oricf.v1.Policy" in names
