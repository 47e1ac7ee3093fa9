"""An endpoint served by several replicas: round robin over the healthy ones, and no frame
lost when one is killed mid-call (real detector processes, SIGKILL)."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from concurrent import futures
from contextlib import ExitStack

import grpc
import pytest
from grpc_health.v1 import health, health_pb2_grpc

from oricf.errors import ConfigError
from oricf.gateway.components import METHODS
from oricf.gateway.config import EndpointConfig, parse_pipeline
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from oricf.v1 import detector_pb2, detector_pb2_grpc
from tests.gateway.test_pipeline import Outputs
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.metrics import scrape
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import RunningService, running_service

DETECT = {"grpc_service": "oricf.v1.Detector", "grpc_method": "Detect"}
FPS = 10.0
FRAMES = 60          # 6 s of camera at FPS
KILL_AFTER = 20      # frames counted before a replica is killed


def detect_calls(metrics_url: str) -> float:
    """Detect calls a replica answered OK, from its own /metrics."""
    found = scrape(metrics_url).find("grpc_server_handled_total", grpc_code="OK", **DETECT)
    return sum(sample.value for sample in found)  # no sample before the first call


@pytest.mark.parametrize("address", [
    "dns:///detector.oricf.svc.cluster.local:50051", "dns:localhost:50051",
    "dns://10.96.0.10/detector.oricf.svc:50051", "ipv4:127.0.0.1:5001,127.0.0.2:5002",
    "ipv6:[::1]:5001,[::1]:5002", "edge.local:50051"])
def test_targets_naming_replicas_are_accepted(address: str) -> None:
    assert EndpointConfig(address=address).address == address


@pytest.mark.parametrize(("address", "error"), [
    ("ipv4:edge.local:5001", "not an IPv4 address"), ("ipv6:[::1]", "not host:port"),
    ("ipv6:::1:5001", r"\[IP\]:PORT"), ("unix:///run/oricf.sock", "not one of"),
    ("dns:///detector", "not host:port"), ("xds:///detector", "not one of")])
def test_other_targets_are_refused(address: str, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        EndpointConfig(address=address)


def test_tls_over_listed_replicas_needs_the_certificate_name() -> None:
    data = {"endpoints": {"detector": {
        "address": "ipv4:127.0.0.1:5001,127.0.0.1:5002", "tls": {"ca": "ca.pem"}}},
        "routes": {}}
    with pytest.raises(ConfigError, match=r"endpoints\.detector: .*tls\.server_name is needed"):
        parse_pipeline(data, "replicas.yaml")


class DiesUnderEveryCall(detector_pb2_grpc.DetectorServicer):
    """A replica whose health says SERVING but whose every call fails as a replica killed
    under a call does (UNAVAILABLE). The real kill is below; this one happens every time."""

    def __init__(self) -> None:
        self.calls = 0

    def Detect(self, request: detector_pb2.DetectRequest,
               context: grpc.ServicerContext) -> detector_pb2.DetectResponse:
        self.calls += 1
        context.abort(grpc.StatusCode.UNAVAILABLE, "connection reset")
        raise AssertionError("unreachable")


@pytest.fixture()
def dying_replica() -> Iterator[tuple[str, DiesUnderEveryCall]]:
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=4))
    servicer = DiesUnderEveryCall()
    detector_pb2_grpc.add_DetectorServicer_to_server(servicer, server)
    health_pb2_grpc.add_HealthServicer_to_server(health.HealthServicer(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    yield f"127.0.0.1:{port}", servicer
    server.stop(0)


def person_request() -> detector_pb2.DetectRequest:
    return detector_pb2.DetectRequest(image=Frame.from_pixels(video_frames([0])[0]).to_proto(),
                                      labels=["person"])


def test_a_call_failing_unavailable_is_answered_by_another_replica(
        dying_replica: tuple[str, DiesUnderEveryCall], detector: RunningService) -> None:
    address, dying = dying_replica
    config = EndpointConfig(address=f"ipv4:{address},{detector.address}", deadline_ms=5000)
    endpoint = Endpoint("detector", config, METHODS["Detect"])
    try:
        request = person_request()  # a raw 768x576 frame: over gRPC's default retry buffer
        for _ in range(6):
            assert count(endpoint.call("Detect", request)) == 4
    finally:
        endpoint.close()
    assert dying.calls >= 2  # round robin sent it calls; each one was retried elsewhere


def test_only_serving_replicas_get_calls() -> None:
    """A replica still loading its model (NOT_SERVING) gets no call until it is SERVING."""
    metrics = {"server": {"metrics": {"listen": "127.0.0.1:0"}}}
    with ExitStack() as stack:
        replicas: list[RunningService] = [
            stack.enter_context(running_service("detector", metrics, load=i < 2))
            for i in range(3)]
        target = "ipv4:" + ",".join(r.address for r in replicas)
        endpoint = Endpoint("detector", EndpointConfig(address=target, deadline_ms=5000),
                            METHODS["Detect"])
        stack.callback(endpoint.close)
        urls = [r.host.metrics_server.url for r in replicas]  # type: ignore[union-attr]
        request = person_request()
        for _ in range(6):
            endpoint.call("Detect", request)
        calls = [detect_calls(u) for u in urls]
        assert calls[0] > 0 and calls[1] > 0 and calls[2] == 0 and sum(calls) == 6
        replicas[2].host.load_model()  # SERVING: the channel's health watch learns it
        deadline = time.monotonic() + 10
        while detect_calls(urls[2]) == 0:
            assert time.monotonic() < deadline, "the replica never got a call once SERVING"
            endpoint.call("Detect", request)


def in_progress(metrics_url: str) -> float:
    return scrape(metrics_url).value("oricf_service_calls_in_progress")


def kill_during_a_call(process: object, metrics_url: str, stop: threading.Event,
                       killed: list[bool]) -> None:
    """SIGKILLs the replica while a Detect call is running in it, so that the call in flight
    dies with it."""
    pid = process.pid  # type: ignore[attr-defined]
    while not stop.is_set():
        if in_progress(metrics_url) >= 1:
            os.killpg(pid, signal.SIGKILL)
            killed.append(True)
            return


def test_no_frame_is_lost_when_a_replica_is_killed_mid_call() -> None:
    ports = [(free_port(), free_port()) for _ in range(3)]
    with ExitStack() as stack:
        processes = [stack.enter_context(oricf_process(
            "serve", "detector", "--listen", f"127.0.0.1:{grpc_port}",
            "--metrics-listen", f"127.0.0.1:{metrics_port}")) for grpc_port, metrics_port in ports]
        for process, (grpc_port, _) in zip(processes, ports, strict=True):
            wait_serving(f"127.0.0.1:{grpc_port}", timeout=180, process=process)
        urls = [f"http://127.0.0.1:{metrics_port}/metrics" for _, metrics_port in ports]
        target = "ipv4:" + ",".join(f"127.0.0.1:{grpc_port}" for grpc_port, _ in ports)
        config = parse_pipeline({
            "endpoints": {"detector": {"address": target, "deadline_ms": 5000}},
            "routes": {"people": {
                "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
                "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
                "post": [{"count": {"label": "person", "into": "people"}}],
                "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32",
                             "from": "people"}]}}}, "replicas test")
        outputs = Outputs()
        pipeline = Pipeline(config, outputs)
        pipeline.start()
        stack.callback(pipeline.stop)
        frames = [Frame.from_pixels(f) for f in video_frames(list(range(0, 600, 10)))]
        stop_killer = threading.Event()
        stack.callback(stop_killer.set)
        killed: list[bool] = []
        before: list[float] = []
        start = time.monotonic()
        for i, frame in enumerate(frames[:FRAMES]):
            if i == KILL_AFTER:
                before = [detect_calls(u) for u in urls]
                threading.Thread(target=kill_during_a_call,
                                 args=(processes[0], urls[0], stop_killer, killed),
                                 daemon=True).start()
            time.sleep(max(0.0, start + i / FPS - time.monotonic()))  # the camera's pace
            pipeline.submit("people", lambda f=frame: {"image": f})
            assert pipeline.idle(10)
        stop_killer.set()
        route, worker = pipeline.routes["people"], pipeline.workers["people"]
        counts = [v for topic, v in outputs.sent if topic == "/human_counter"]
        after = [detect_calls(u) for u in urls[1:]]
    assert killed, "the replica never had a call in progress to be killed in"
    assert all(n > 0 for n in before), f"calls were not spread over the replicas: {before}"
    assert len(counts) == FRAMES, f"{FRAMES - len(counts)} frames lost"
    assert worker.stats.dropped == 0 and route.stats.errors == {}
    assert all(a > b for a, b in zip(after, before[1:], strict=True))  # the two left share it
