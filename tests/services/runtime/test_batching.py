"""Dynamic batching in the detector: the real YOLOX-Nano behind a real gRPC server.

A batch runs when max_batch_size requests wait or max_queue_delay_ms has passed since the
oldest came. The tests set the delay to its maximum (10 s) and the batch size to the number
of requests they send, so a batch forms because the requests are there, never because of
how fast this machine is; requests that must stay queued stay queued for the same reason.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import grpc
import pytest

from oricf.services.runtime.limits import PUSHBACK_KEY
from oricf.v1 import detector_pb2, detector_pb2_grpc
from tests.services.test_detector import raw_request
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.metrics import Scrape, scrape
from tests.support.services import RunningService, running_service

CLIENTS = 4
HOLD_MS = 10_000  # the longest delay: a batch never runs early for lack of requests
# How long a test waits for something that must happen (a hang bound, not a measurement).
WAIT_S = 60


def batching(max_batch_size: int = CLIENTS, **more: object) -> dict[str, object]:
    return {"batching": {"max_batch_size": max_batch_size, "max_queue_delay_ms": HOLD_MS,
                         **more},
            "server": {"metrics": {"listen": "127.0.0.1:0"}}}


@pytest.fixture(scope="module")
def requests() -> list[detector_pb2.DetectRequest]:
    return [raw_request(f, labels=["person"], frame_id=i)
            for i, f in enumerate(video_frames([0, 200, 400, 600]))]


def metrics(service: RunningService) -> Scrape:
    server = service.host.metrics_server
    assert server is not None
    return scrape(f"http://127.0.0.1:{server.port}/metrics")


def batch_metric(service: RunningService, name: str, **labels: str) -> float:
    return metrics(service).value(name, service="detector", batcher="detector", **labels)


def wait_until_queued(service: RunningService, count: int) -> None:
    """Blocks until `count` requests wait in the batch queue."""
    batcher = service.host.slot.batchers[0]
    deadline = time.monotonic() + WAIT_S
    while batcher.queued < count:
        assert time.monotonic() < deadline, "requests never reached the queue"
        time.sleep(0.01)


def detect_at_once(service: RunningService, requests: list[detector_pb2.DetectRequest]
                   ) -> list[detector_pb2.DetectResponse]:
    """Each request from a caller of its own (one channel each: separate robots, not one
    client's calls), all at once."""
    channels = [grpc.insecure_channel(service.address) for _ in requests]
    try:
        with ThreadPoolExecutor(len(requests)) as pool:
            return list(pool.map(
                lambda pair: detector_pb2_grpc.DetectorStub(pair[0]).Detect(
                    pair[1], timeout=WAIT_S), zip(channels, requests, strict=True)))
    finally:
        for channel in channels:
            channel.close()


def boxes(response: detector_pb2.DetectResponse) -> list[tuple[str, float, tuple[float, ...]]]:
    return [(d.label, d.score, (d.box.x_min, d.box.y_min, d.box.x_max, d.box.y_max))
            for d in response.detections]


@pytest.fixture(scope="module")
def unbatched(requests: list[detector_pb2.DetectRequest], detector: RunningService
              ) -> list[detector_pb2.DetectResponse]:
    stub = detector_pb2_grpc.DetectorStub(detector.channel)
    return [stub.Detect(r, timeout=WAIT_S) for r in requests]


def test_concurrent_callers_share_one_batch_and_get_their_own_answers(
        requests: list[detector_pb2.DetectRequest],
        unbatched: list[detector_pb2.DetectResponse]) -> None:
    with running_service("detector", batching()) as service:
        answers = detect_at_once(service, requests)
        assert batch_metric(service, "oricf_batch_size_count") == 1
        assert batch_metric(service, "oricf_batch_size_sum") == CLIENTS
        assert batch_metric(service, "oricf_batch_size_bucket", le="2.0") == 0
    for got, alone in zip(answers, unbatched, strict=True):
        assert got.frame_id == alone.frame_id
        assert count(got, "person") == count(alone, "person") >= 2
        assert [(label, pytest.approx(score, abs=1e-4), pytest.approx(box, abs=1e-2))
                for label, score, box in boxes(alone)] == boxes(got)


def test_idle_instances_share_a_released_batch(
        requests: list[detector_pb2.DetectRequest],
        unbatched: list[detector_pb2.DetectResponse]) -> None:
    # Two requests fill a batch of two; two idle instances run one each (on two cores).
    with running_service("detector", batching(max_batch_size=2, instances=2)) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        with ThreadPoolExecutor(2) as pool:
            answers = list(pool.map(lambda r: stub.Detect(r, timeout=WAIT_S), requests[:2]))
        assert [count(a, "person") for a in answers] == \
            [count(u, "person") for u in unbatched[:2]]
        assert batch_metric(service, "oricf_batch_size_count") == 2
        assert batch_metric(service, "oricf_batch_size_sum") == 2


def test_a_stream_is_batched_with_unary_callers(
        requests: list[detector_pb2.DetectRequest],
        unbatched: list[detector_pb2.DetectResponse]) -> None:
    with running_service("detector", batching(max_batch_size=2)) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        with ThreadPoolExecutor(1) as pool:
            unary = pool.submit(stub.Detect, requests[0], timeout=WAIT_S)
            wait_until_queued(service, 1)
            streamed = list(stub.DetectStream(iter(requests[1:2]), timeout=WAIT_S))
            assert count(unary.result(), "person") == count(unbatched[0], "person")
        assert [count(r, "person") for r in streamed] == [count(unbatched[1], "person")]
        assert batch_metric(service, "oricf_batch_size_sum") == 2


def test_a_deadline_that_passes_in_the_queue_is_never_run(
        requests: list[detector_pb2.DetectRequest]) -> None:
    with running_service("detector", batching()) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        with pytest.raises(grpc.RpcError) as error:
            stub.Detect(requests[0], timeout=2)  # the batch waits 10 s for 3 more
        assert error.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
        wait_for_drop(service, "deadline")
        assert batch_metric(service, "oricf_batch_size_count") == 0
        assert service.host.slot.batchers[0].queued == 0


def test_a_caller_that_goes_away_leaves_the_queue(
        requests: list[detector_pb2.DetectRequest]) -> None:
    with running_service("detector", batching()) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        call = stub.Detect.future(requests[0], timeout=WAIT_S)
        wait_until_queued(service, 1)
        call.cancel()
        wait_for_drop(service, "cancelled")
        assert service.host.slot.batchers[0].queued == 0
        assert batch_metric(service, "oricf_batch_size_count") == 0


def wait_for_drop(service: RunningService, reason: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while batch_metric(service, "oricf_batch_dropped_total", reason=reason) < 1:
        assert time.monotonic() < deadline, f"no request dropped ({reason})"
        time.sleep(0.05)


def test_a_full_queue_refuses_with_pushback_and_a_stop_drains_it(
        requests: list[detector_pb2.DetectRequest],
        unbatched: list[detector_pb2.DetectResponse]) -> None:
    with running_service("detector", batching(max_queue_size=1)) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        queued = stub.Detect.future(requests[0], timeout=WAIT_S)
        wait_until_queued(service, 1)
        with pytest.raises(grpc.RpcError) as error:
            stub.Detect(requests[1], timeout=WAIT_S)
        assert error.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert "batch queue is full" in (error.value.details() or "")
        pushback = dict(error.value.trailing_metadata() or ())[PUSHBACK_KEY]
        assert int(pushback) >= service.host.config.server.retry_after_ms
        assert batch_metric(service, "oricf_batch_dropped_total", reason="refused") == 1
        # SIGTERM's path: the queued request is run at once (no waiting for the batch to
        # fill) and answered before the service stops.
        assert service.host.stop(grace=WAIT_S)
        assert count(queued.result(), "person") == count(unbatched[0], "person")



def test_a_fixed_batch_size_runs_padded_batches_with_each_callers_own_answers(
        requests: list[detector_pb2.DetectRequest],
        unbatched: list[detector_pb2.DetectResponse]) -> None:
    """batching.fixed_size: every batch at max_batch_size rows (what a GPU needs), here
    forced on the CPU: three callers' frames in a batch padded to 8 answer as alone."""
    settings = batching(max_batch_size=8, fixed_size=True)
    settings["batching"]["max_queue_delay_ms"] = 200  # type: ignore[index]
    with running_service("detector", settings) as service:
        assert service.host.slot.peek().model.pad_to == 8
        answers = detect_at_once(service, requests[:3])
    for got, alone in zip(answers, unbatched, strict=False):
        assert got.frame_id == alone.frame_id
        assert [(label, pytest.approx(score, abs=1e-4), pytest.approx(box, abs=1e-2))
                for label, score, box in boxes(alone)] == boxes(got)
