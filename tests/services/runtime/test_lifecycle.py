"""The shared runtime: health around loading, limits, reflection, SIGTERM drain, bad config."""

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.config import REPO_ROOT
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import image
from tests.support.detections import count
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import running_service

SERVING = health_pb2.HealthCheckResponse.SERVING
NOT_SERVING = health_pb2.HealthCheckResponse.NOT_SERVING


def person_request(frame_id: int = 0) -> detector_pb2.DetectRequest:
    data = image("person.jpg").read_bytes()
    return detector_pb2.DetectRequest(image=common_pb2.Image(data=data, encoding="jpeg"),
                                      labels=["person"], frame_id=frame_id)


def health(channel: grpc.Channel, service: str = "") -> int:
    request = health_pb2.HealthCheckRequest(service=service)
    return int(health_pb2_grpc.HealthStub(channel).Check(request, timeout=5).status)


def test_health_is_serving_only_once_the_model_has_loaded() -> None:
    with running_service("detector", load=False) as service:
        assert health(service.channel) == NOT_SERVING
        assert health(service.channel, "oricf.v1.Detector") == NOT_SERVING
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        with pytest.raises(grpc.RpcError) as err:
            stub.Detect(person_request(), timeout=5)
        assert err.value.code() == grpc.StatusCode.UNAVAILABLE
        assert "still loading" in err.value.details()

        service.host.load_model()
        assert health(service.channel) == SERVING
        assert health(service.channel, "oricf.v1.Detector") == SERVING
        assert count(stub.Detect(person_request(), timeout=5), "person") == 1


def test_calls_over_the_concurrency_limit_are_refused_at_once() -> None:
    with running_service("detector", {"server": {"max_concurrent_rpcs": 1}}) as service:
        stub = detector_pb2_grpc.DetectorStub(service.channel)
        release = threading.Event()

        def held_open() -> Iterator[detector_pb2.DetectRequest]:
            yield person_request()
            release.wait(10)

        stream = stub.DetectStream(held_open(), timeout=20)
        assert count(next(stream), "person") == 1  # the one allowed call is now in flight
        with pytest.raises(grpc.RpcError) as err:
            stub.Detect(person_request(), timeout=10)
        # Refused while the allowed call is still held open: not queued behind it.
        assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert not release.is_set()
        pushback = dict(err.value.trailing_metadata() or ())["grpc-retry-pushback-ms"]
        assert 100 <= int(pushback) <= 200  # retry_after_ms 100, jittered up to 2x
        assert f"retry in {pushback} ms" in (err.value.details() or "")
        health_stub = health_pb2_grpc.HealthStub(service.channel)  # busy, and still alive
        assert health_stub.Check(health_pb2.HealthCheckRequest(), timeout=5).status == SERVING
        release.set()
        assert list(stream) == []
        assert count(stub.Detect(person_request(), timeout=10), "person") == 1


def test_sigterm_drains_in_flight_calls_and_exits_zero() -> None:
    port = free_port()
    address = f"127.0.0.1:{port}"
    with oricf_process("serve", "detector", "--listen", address) as process:
        wait_serving(address, timeout=120, process=process)
        channel = grpc.insecure_channel(address)
        watch = health_pb2_grpc.HealthStub(channel).Watch(
            health_pb2.HealthCheckRequest(service=""), timeout=30)
        assert next(watch).status == SERVING
        terminated = threading.Event()

        def frames() -> Iterator[detector_pb2.DetectRequest]:
            yield person_request(1)
            process.send_signal(signal.SIGTERM)
            terminated.set()
            time.sleep(1.0)  # the call is still in flight while the service drains
            yield person_request(2)
            yield person_request(3)

        responses = list(detector_pb2_grpc.DetectorStub(channel).DetectStream(frames(), timeout=30))
        assert terminated.is_set()
        assert [r.frame_id for r in responses] == [1, 2, 3]
        assert all(count(r, "person") == 1 for r in responses)
        assert next(watch).status == NOT_SERVING
        assert process.wait(timeout=20) == 0
        channel.close()
        output = process.stdout.read() if process.stdout else ""
        assert "draining" in output and "stopped" in output


def test_invalid_config_exits_non_zero_naming_file_and_key(tmp_path: Path) -> None:
    config = tmp_path / "detector.yaml"
    config.write_text("detection:\n  min_score: 1.5\n  labelz: [person]\n")
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "serve", "detector", "--config", str(config)],
        capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2
    assert f"{config}: detection.min_score: Input should be less than or equal to 1" \
        in result.stderr
    assert f"{config}: detection.labelz: unknown key" in result.stderr


def test_a_model_no_provider_here_can_run_is_refused(tmp_path: Path) -> None:
    declaration = tmp_path / "cuda.yaml"
    declaration.write_text(
        (REPO_ROOT / "configs/models/yolox-nano.yaml").read_text().replace(
            "backend: {engine: onnxruntime, threads: 1}",
            "backend: {engine: onnxruntime, providers: [CUDAExecutionProvider]}")
        .replace("labels/coco80.txt", str(REPO_ROOT / "configs/models/labels/coco80.txt")))
    config = tmp_path / "detector.yaml"
    config.write_text(f"model: {declaration}\n")
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "serve", "detector", "--config", str(config),
         "--listen", "127.0.0.1:0"], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2
    assert ("backend.providers: none of CUDAExecutionProvider is in this onnxruntime build"
            in result.stderr)


def test_sigterm_stop_is_bounded_even_with_streams_held_open(tmp_path: Path) -> None:
    """Streams that carried undecodable bytes and a stream the client never ends: the
    service still exits within its grace period and a margin, and says so."""
    config = tmp_path / "detector.yaml"
    config.write_text("server: {grace_s: 1}\n")
    port = free_port()
    with oricf_process("serve", "detector", "--config", str(config), "--listen",
                       f"127.0.0.1:{port}") as process:
        wait_serving(f"127.0.0.1:{port}", process=process)
        channel = grpc.insecure_channel(f"127.0.0.1:{port}")
        release = threading.Event()
        stream = channel.stream_stream("/oricf.v1.Detector/DetectStream")

        def garbage_then_hold() -> Iterator[bytes]:
            yield b"\x0a\xff\xff\xff\x0f"
            release.wait(60)

        def held() -> Iterator[detector_pb2.DetectRequest]:
            yield person_request(1)
            release.wait(60)

        responses = [stream(garbage_then_hold(), timeout=60) for _ in range(10)]
        responses.append(detector_pb2_grpc.DetectorStub(channel).DetectStream(held(),
                                                                              timeout=60))
        pulled = []
        for response in responses:
            pulled.append(threading.Thread(target=lambda r=response: _drain(r), daemon=True))
            pulled[-1].start()
        time.sleep(1.0)
        process.send_signal(signal.SIGTERM)
        # The streams are held for 60 s: an exit within this wait is one that did not wait
        # for them.
        code = process.wait(timeout=30)
        release.set()
        channel.close()
        output = process.stdout.read() if process.stdout else ""
        assert code in (0, 1), output
        assert "stopped" in output or "exiting anyway" in output, output


def _drain(responses: Iterator[object]) -> None:
    try:
        for _ in responses:
            pass
    except grpc.RpcError:
        pass
