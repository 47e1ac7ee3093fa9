"""Endpoint failover against real gRPC servers: a real detector, a dead port, a hung host."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator

import grpc
import pytest

from oricf.gateway.components import METHODS
from oricf.gateway.endpoints import Endpoint, EndpointConfig, RetryConfig
from oricf.gateway.values import Frame
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import video_frames
from tests.support.detections import count
from tests.support.processes import free_port
from tests.support.services import RunningService, running_service

DETECTOR = METHODS["Detect"]


@pytest.fixture(scope="module")
def request_0() -> detector_pb2.DetectRequest:
    return detector_pb2.DetectRequest(image=Frame.from_pixels(video_frames([0])[0]).to_proto(),
                                      labels=["person"])


def endpoint(address: str, fallback: str | None = None, deadline_ms: int = 2000) -> Endpoint:
    config = EndpointConfig(address=address, fallback=fallback, deadline_ms=deadline_ms,
                            probe_interval_s=0.1)
    return Endpoint("detector", config, DETECTOR)


@pytest.fixture()
def hung_address() -> Iterator[str]:
    """A host that accepts connections, reads, and never answers (a hung machine)."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    held: list[socket.socket] = []

    def accept_and_hold() -> None:
        with contextlib.suppress(OSError):
            while True:
                connection, _ = listener.accept()
                held.append(connection)

    threading.Thread(target=accept_and_hold, daemon=True).start()
    yield f"127.0.0.1:{listener.getsockname()[1]}"
    listener.close()
    for connection in held:
        connection.close()


def test_without_a_fallback_errors_reach_the_caller(request_0: detector_pb2.DetectRequest
                                                     ) -> None:
    dead = endpoint(f"127.0.0.1:{free_port()}")
    with pytest.raises(grpc.RpcError) as error:
        dead.call("Detect", request_0)
    dead.close()
    assert error.value.code() == grpc.StatusCode.UNAVAILABLE


def test_client_errors_do_not_fail_over(request_0: detector_pb2.DetectRequest,
                                        detector: RunningService) -> None:
    # The session's detector at both ends: a failover would show in the endpoint alone.
    ep = endpoint(detector.address, detector.address)
    bad = detector_pb2.DetectRequest(image=common_pb2.Image(data=b"x", encoding="jpeg"))
    with pytest.raises(grpc.RpcError) as error:
        ep.call("Detect", bad)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert ep.active is ep.primary and ep.failovers == 0
    assert count(ep.call("Detect", request_0)) == 4
    ep.close()


def test_fails_over_when_unavailable_and_returns_when_serving(
        request_0: detector_pb2.DetectRequest) -> None:
    port = free_port()
    with running_service("detector") as fallback:
        ep = endpoint(f"127.0.0.1:{port}", fallback.address)
        assert count(ep.call("Detect", request_0)) == 4  # answered by the fallback
        assert ep.active is ep.fallback and ep.failovers == 1
        assert count(ep.call("Detect", request_0)) == 4
        assert ep.failovers == 1  # no second switch while already on the fallback
        with running_service("detector", {"server": {"listen": f"127.0.0.1:{port}"}}):
            deadline = time.monotonic() + 10
            while ep.active is not ep.primary and time.monotonic() < deadline:
                time.sleep(0.05)
            assert ep.active is ep.primary and ep.recoveries == 1
            fallback.host.stop(grace=0)
            assert count(ep.call("Detect", request_0)) == 4  # the primary answers
        ep.close()


def counting_probes(ep: Endpoint) -> list[bool]:
    """Records every answer of the primary's health probe (the real probe, still called)."""
    answers: list[bool] = []
    serving = ep.primary.serving

    def probe() -> bool:
        answers.append(serving())
        return answers[-1]

    ep.primary.serving = probe  # type: ignore[method-assign]
    return answers


def wait_until(condition: Callable[[], bool], timeout: float = 10) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "not reached within the timeout"
        time.sleep(0.02)


def test_a_primary_is_returned_to_once_serving_and_not_before(
        request_0: detector_pb2.DetectRequest) -> None:
    port = free_port()
    with running_service("detector") as fallback:
        ep = endpoint(f"127.0.0.1:{port}", fallback.address)
        probes = counting_probes(ep)
        ep.call("Detect", request_0)
        assert ep.active is ep.fallback
        with running_service("detector", {"server": {"listen": f"127.0.0.1:{port}"}},
                             load=False) as primary:  # up, but NOT_SERVING: no model yet
            # The probe keeps asking the server that is up; each answer is "not serving".
            asked = len(probes)
            wait_until(lambda: len(probes) >= asked + 5 or ep.active is ep.primary)
            assert ep.active is ep.fallback and ep.recoveries == 0 and True not in probes
            primary.host.load_model()
            wait_until(lambda: ep.active is ep.primary)
            assert ep.recoveries == 1 and probes[-1] is True
            fallback.host.stop(grace=0)
            assert count(ep.call("Detect", request_0)) == 4  # the primary answers
        ep.close()


def test_deadline_exceeded_fails_over(hung_address: str, request_0: detector_pb2.DetectRequest,
                                      caplog: pytest.LogCaptureFixture,
                                      detector: RunningService) -> None:
    ep = endpoint(hung_address, detector.address, deadline_ms=300)
    started = time.monotonic()
    assert count(ep.call("Detect", request_0)) == 4
    # The hung primary had its whole deadline (no earlier give-up); how long a
    # failover takes is `oricf bench link`'s figure (the longest gap between counts).
    assert time.monotonic() - started >= 0.3
    assert ep.active is ep.fallback
    assert "failed (DEADLINE_EXCEEDED: Deadline Exceeded); using fallback" in caplog.text
    ep.close()


def _busy_detector_call(attempts: int, request_0: detector_pb2.DetectRequest,
                        hold_s: float) -> tuple[Endpoint, object]:
    """A detector that takes one call at a time, held by a stream for hold_s; returns the
    endpoint and what its Detect call gave (a response or the RpcError)."""
    overrides = {"server": {"max_concurrent_rpcs": 1, "retry_after_ms": 150}}
    with running_service("detector", overrides) as busy:
        release = threading.Event()

        def held() -> Iterator[detector_pb2.DetectRequest]:
            yield request_0
            release.wait(10)

        stream = detector_pb2_grpc.DetectorStub(busy.channel).DetectStream(held(), timeout=20)
        next(stream)  # the one allowed call is in flight
        threading.Timer(hold_s, release.set).start()
        config = EndpointConfig(address=busy.address, deadline_ms=5000,
                                retry=RetryConfig(attempts=attempts, initial_backoff_ms=100))
        ep = Endpoint("detector", config, DETECTOR)
        try:
            result: object = ep.call("Detect", request_0)
        except grpc.RpcError as exc:
            result = exc
        release.set()
        list(stream)
        ep.close()
        return ep, result


def test_a_busy_service_is_retried_after_its_pushback(
        request_0: detector_pb2.DetectRequest) -> None:
    ep, result = _busy_detector_call(attempts=5, request_0=request_0, hold_s=0.4)
    assert isinstance(result, detector_pb2.DetectResponse) and count(result) == 4
    assert 1 <= ep.retries <= 5


def test_without_retries_the_refusal_reaches_the_caller(
        request_0: detector_pb2.DetectRequest) -> None:
    ep, result = _busy_detector_call(attempts=0, request_0=request_0, hold_s=0.4)
    assert isinstance(result, grpc.RpcError)
    assert result.code() == grpc.StatusCode.RESOURCE_EXHAUSTED and ep.retries == 0
