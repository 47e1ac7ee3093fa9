"""A real detector with metrics on: real calls with every outcome, then a scrape of
/metrics read with prometheus_client's own text parser. Also `oricf serve --metrics-listen`."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import onnxruntime
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from prometheus_client.samples import Sample

from oricf.errors import ConfigError
from oricf.gateway.values import Frame
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc
from tests.support.data import video_frames
from tests.support.metrics import Scrape, scrape
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import RunningService, running_service

TOKEN = "metrics-test-token"
DETECTOR = "oricf.v1.Detector"


@pytest.fixture(scope="module")
def detector_metered(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningService]:
    tokens = tmp_path_factory.mktemp("auth") / "tokens"
    tokens.write_text(f"{TOKEN}\n")
    server = {"auth": {"file": str(tokens)}, "metrics": {"listen": "127.0.0.1:0"}}
    with running_service("detector", {"server": server}) as service:
        yield service


def metrics_url(service: RunningService) -> str:
    assert service.host.metrics_server is not None
    return f"http://127.0.0.1:{service.host.metrics_server.port}/metrics"


def frame_request() -> detector_pb2.DetectRequest:
    return detector_pb2.DetectRequest(image=Frame.from_pixels(video_frames([0])[0]).to_proto(),
                                      labels=["person"])


def codes_after_calls(service: RunningService) -> dict[str, grpc.StatusCode]:
    """One call per outcome: OK, a bad image, no token, a stream of three, health."""
    stub = detector_pb2_grpc.DetectorStub(service.channel)
    auth = (("authorization", f"Bearer {TOKEN}"),)
    codes = {}
    stub.Detect(frame_request(), metadata=auth, timeout=10)
    codes["ok"] = grpc.StatusCode.OK
    bad = detector_pb2.DetectRequest(image=common_pb2.Image(data=b"x", encoding="jpeg"))
    for name, request, metadata in (("bad", bad, auth), ("no token", frame_request(), ())):
        with pytest.raises(grpc.RpcError) as error:
            stub.Detect(request, metadata=metadata, timeout=10)
        codes[name] = error.value.code()
    answers = list(stub.DetectStream(iter([frame_request()] * 3), metadata=auth, timeout=30))
    assert len(answers) == 3
    health_pb2_grpc.HealthStub(service.channel).Check(health_pb2.HealthCheckRequest(),
                                                      timeout=5)
    return codes


@pytest.fixture(scope="module")
def scraped(detector_metered: RunningService) -> Scrape:
    codes = codes_after_calls(detector_metered)
    assert codes == {"ok": grpc.StatusCode.OK, "bad": grpc.StatusCode.INVALID_ARGUMENT,
                     "no token": grpc.StatusCode.UNAUTHENTICATED}
    return scrape(metrics_url(detector_metered))


def test_calls_are_counted_by_method_and_status_code(scraped: Scrape) -> None:
    unary = {"grpc_type": "unary", "grpc_service": DETECTOR, "grpc_method": "Detect"}
    handled = "grpc_server_handled_total"
    assert scraped.value(handled, **unary, grpc_code="OK") == 1
    assert scraped.value(handled, **unary, grpc_code="INVALID_ARGUMENT") == 1
    assert scraped.value(handled, **unary, grpc_code="UNAUTHENTICATED") == 1
    assert len(scraped.find(handled, **unary)) == 3  # no other code for Detect
    assert scraped.value("grpc_server_started_total", **unary) == 3
    assert scraped.value("grpc_server_msg_received_total", **unary) == 3
    assert scraped.value("grpc_server_msg_sent_total", **unary) == 1  # only the OK call
    health = {"grpc_service": "grpc.health.v1.Health", "grpc_method": "Check"}
    assert scraped.value(handled, **health, grpc_code="OK") == 1
    assert scraped.families[handled.removesuffix("_total")] == "counter"


def test_a_stream_counts_once_with_its_messages(scraped: Scrape) -> None:
    stream = {"grpc_type": "bidi_stream", "grpc_service": DETECTOR,
              "grpc_method": "DetectStream"}
    assert scraped.value("grpc_server_handled_total", **stream, grpc_code="OK") == 1
    assert scraped.value("grpc_server_msg_received_total", **stream) == 3
    assert scraped.value("grpc_server_msg_sent_total", **stream) == 3


def test_call_durations_are_a_histogram_in_seconds(scraped: Scrape) -> None:
    detect = {"grpc_type": "unary", "grpc_service": DETECTOR, "grpc_method": "Detect"}
    assert scraped.families["grpc_server_handling_seconds"] == "histogram"
    assert scraped.value("grpc_server_handling_seconds_count", **detect) == 3
    assert 0 < scraped.value("grpc_server_handling_seconds_sum", **detect) < 10
    buckets = scraped.find("grpc_server_handling_seconds_bucket", **detect)
    assert [b.value for b in buckets] == sorted(b.value for b in buckets)  # cumulative
    assert scraped.value("grpc_server_handling_seconds_bucket", **detect, le="+Inf") == 3


def test_model_load_and_the_call_limit(scraped: Scrape) -> None:
    model = {"service": "detector", "model": "yolox-nano"}
    assert scraped.families["oricf_model_load_seconds"] == "gauge"
    assert 0 < scraped.value("oricf_model_load_seconds", **model) < 120
    assert scraped.value("oricf_model_ready", **model) == 1
    # Where it runs: the execution provider running it, as its log line names it.
    assert scraped.families["oricf_model_info"] == "gauge"
    assert scraped.value("oricf_model_info", **model, provider="CPUExecutionProvider",
                         runtime=f"onnxruntime {onnxruntime.__version__}") == 1
    assert scraped.value("oricf_service_calls_limit", service="detector") == 8
    assert scraped.value("oricf_service_calls_in_progress", service="detector") == 0
    assert scraped.value("process_resident_memory_bytes") > 0


def test_a_stream_the_caller_cancels_is_counted_cancelled(detector_metered: RunningService) -> None:
    stub = detector_pb2_grpc.DetectorStub(detector_metered.channel)
    labels = {"grpc_method": "DetectStream", "grpc_code": "CANCELLED"}
    assert scrape(metrics_url(detector_metered)).find("grpc_server_handled_total", **labels) == []
    # Cancelled while the service works on the frames sent: a cancel that meets a handler
    # which has just seen its request stream end is a race grpcio may report either way.
    stream = stub.DetectStream(iter([frame_request()] * 10), timeout=30,
                               metadata=(("authorization", f"Bearer {TOKEN}"),))
    next(stream)
    stream.cancel()
    assert [s.value for s in wait_for(detector_metered, **labels)] == [1]


def test_a_stream_past_its_deadline_is_counted_deadline_exceeded(
        detector_metered: RunningService) -> None:
    stub = detector_pb2_grpc.DetectorStub(detector_metered.channel)
    release = threading.Event()

    def requests() -> Iterator[detector_pb2.DetectRequest]:
        yield frame_request()
        release.wait(10)

    labels = {"grpc_method": "DetectStream", "grpc_code": "DEADLINE_EXCEEDED"}
    with pytest.raises(grpc.RpcError) as error:
        list(stub.DetectStream(requests(), timeout=0.5,
                               metadata=(("authorization", f"Bearer {TOKEN}"),)))
    release.set()
    assert error.value.code() == grpc.StatusCode.DEADLINE_EXCEEDED
    assert [s.value for s in wait_for(detector_metered, **labels)] == [1]


def wait_for(service: RunningService, **labels: str) -> list[Sample]:
    """grpc_server_handled_total samples with labels, once there are some (a stream's
    handler ends shortly after its caller has gone)."""
    deadline = time.monotonic() + 10
    while not (found := scrape(metrics_url(service)).find("grpc_server_handled_total",
                                                           **labels)):
        assert time.monotonic() < deadline, f"no {labels} within 10 s"
        time.sleep(0.05)
    return found


def test_a_port_in_use_is_a_config_error() -> None:
    with running_service("detector", {"server": {"metrics": {"listen": "127.0.0.1:0"}}}) as a:
        assert a.host.metrics_server is not None
        taken = f"127.0.0.1:{a.host.metrics_server.port}"
        with pytest.raises(ConfigError, match=f"metrics: cannot listen on {taken}"), \
                running_service("detector", {"server": {"metrics": {"listen": taken}}}):
            pass


def test_oricf_serve_metrics_listen(tmp_path: Path) -> None:
    address, metrics = f"127.0.0.1:{free_port()}", f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "detector", "--listen", address,
                       "--metrics-listen", metrics) as server:
        wait_serving(address, timeout=120, process=server)
        scraped = scrape(f"http://{metrics}/metrics")
    assert scraped.value("oricf_model_ready", service="detector") == 1
    assert scraped.value("oricf_model_load_seconds", service="detector") > 0
    assert scraped.value("grpc_server_handled_total", grpc_service="grpc.health.v1.Health",
                         grpc_code="OK") >= 1  # wait_serving's own checks
