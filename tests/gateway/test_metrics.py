"""The gateway's /metrics: a real Pipeline against real detectors (a primary that dies and a
fallback), inputs that are replaced, dropped, refused and failed, scraped over HTTP and read
with prometheus_client's own parser; then `oricf gateway --metrics-listen` in a process."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from rclpy.context import Context

from oricf.config import config_dir
from oricf.errors import InvalidInput
from oricf.gateway.components import Emitter
from oricf.gateway.config import parse_pipeline
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.route import Loader
from oricf.gateway.values import Frame, Record
from tests.gateway.pipelines import people_qa
from tests.gateway.ros.gateway_node import running_gateway
from tests.support.data import video_frames, video_path
from tests.support.metrics import Scrape, scrape
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.services import RunningService, running_service

DETECT = {"service": "detector", "method": "Detect", "labels": ["person"]}


def pipeline(primary: str, fallback: str) -> Pipeline:
    data = {
        "endpoints": {"detector": {"address": primary, "fallback": fallback,
                                   "deadline_ms": 5000, "probe_interval_s": 60}},
        "routes": {
            "camera": {"input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
                       "call": DETECT, "post": [{"count": {"label": "person"}}],
                       "outputs": [{"product": "people", "from": "count"}]},
            "queued": {"input": {"url": "not-opened.mp4", "keep": "queue", "queue_size": 2},
                       "call": DETECT, "outputs": [{"product": "queued", "from": "detections"}]}},
        "metrics": {"listen": "127.0.0.1:0"}}
    return Pipeline(parse_pipeline(data, "metrics test"), Emitter())


@pytest.fixture()
def detectors(detector: RunningService) -> Iterator[tuple[RunningService, RunningService]]:
    """A primary of its own (the test stops it) and the session's detector as its fallback."""
    with running_service("detector") as primary:
        yield primary, detector


def frame_loader() -> Loader:
    frame = Frame.from_pixels(video_frames([0])[0])
    return lambda: {"image": frame}


def held(load: Loader, release: threading.Event, taken: threading.Event) -> Loader:
    """An input that keeps its route busy until released."""
    def hold() -> Record:
        taken.set()
        release.wait(10)
        return load()

    return hold


def fails(exc: Exception) -> Callable[[], Record]:
    def load() -> Record:
        raise exc

    return load


def read(p: Pipeline) -> Scrape:
    assert p.metrics_server is not None
    return scrape(f"http://127.0.0.1:{p.metrics_server.port}/metrics")


def busy_route_scrape(p: Pipeline, route: str, more: int) -> Scrape:
    """Holds the route on one input, submits `more`, scrapes while it is held."""
    release, taken = threading.Event(), threading.Event()
    p.submit(route, held(frame_loader(), release, taken))
    assert taken.wait(10)
    for _ in range(more):
        p.submit(route, frame_loader())
    scraped = read(p)
    release.set()
    assert p.idle(10)
    return scraped


def test_route_and_endpoint_metrics(detectors: tuple[RunningService, RunningService]) -> None:
    primary, fallback = detectors
    p = pipeline(primary.address, fallback.address)
    p.start()
    try:
        busy = busy_route_scrape(p, "camera", 3)  # 1 held, 3 more: 2 replaced, 1 waits
        assert busy.value("oricf_gateway_route_queue_depth", route="camera") == 1
        assert busy.value("oricf_gateway_route_in_progress", route="camera") == 1
        busy = busy_route_scrape(p, "queued", 4)  # 1 held, 4 more: 2 dropped, 2 wait
        assert busy.value("oricf_gateway_route_queue_depth", route="queued") == 2
        p.submit("camera", fails(InvalidInput("not an image")))
        p.submit("queued", lambda: {"image": Frame(b"x", "jpeg")})  # the service refuses it
        p.submit("queued", fails(RuntimeError("a bug")))
        assert p.idle(10)
        before_failover = read(p)
        primary.host.stop(grace=0)
        p.submit("camera", frame_loader())  # UNAVAILABLE on the primary: the fallback answers
        assert p.idle(10)
        scraped = read(p)
    finally:
        p.stop()
    assert before_failover.value("oricf_gateway_endpoint_failovers_total",
                                 endpoint="detector") == 0
    check_inputs(scraped)
    check_outcomes(scraped)
    check_failover(scraped, primary.address, fallback.address)


def check_inputs(scraped: Scrape) -> None:
    value = scraped.value
    assert value("oricf_gateway_route_inputs_received_total", route="camera") == 4 + 1 + 1
    assert value("oricf_gateway_route_inputs_replaced_total", route="camera") == 2
    assert value("oricf_gateway_route_inputs_dropped_total", route="camera") == 0
    assert value("oricf_gateway_route_inputs_received_total", route="queued") == 5 + 2
    assert value("oricf_gateway_route_inputs_dropped_total", route="queued") == 2
    assert value("oricf_gateway_route_inputs_replaced_total", route="queued") == 0
    assert value("oricf_gateway_route_queue_depth", route="camera") == 0
    assert scraped.families["oricf_gateway_route_queue_depth"] == "gauge"
    assert scraped.families["oricf_gateway_route_inputs_received"] == "counter"


def check_outcomes(scraped: Scrape) -> None:
    handled = "oricf_gateway_route_inputs_handled_total"
    camera = {s.labels["outcome"]: s.value for s in scraped.find(handled, route="camera")}
    assert camera == {"ok": 3, "bad_input": 1, "skipped": 0, "call_error": 0, "internal": 0}
    queued = {s.labels["outcome"]: s.value for s in scraped.find(handled, route="queued")}
    assert queued == {"ok": 3, "bad_input": 0, "skipped": 0, "call_error": 1, "internal": 1}
    errors = scraped.find("oricf_gateway_route_call_errors_total", route="queued")
    assert [(s.labels["code"], s.value) for s in errors] == [("INVALID_ARGUMENT", 1)]
    assert scraped.families["oricf_gateway_route_latency_seconds"] == "histogram"
    count = scraped.value("oricf_gateway_route_latency_seconds_count", route="camera")
    assert count == 3  # the inputs handled ok
    assert 0 < scraped.value("oricf_gateway_route_latency_seconds_sum", route="camera") < 30
    assert scraped.value("oricf_gateway_route_latency_seconds_bucket", route="camera",
                         le="+Inf") == 3


def check_failover(scraped: Scrape, primary: str, fallback: str) -> None:
    assert scraped.value("oricf_gateway_endpoint_failovers_total", endpoint="detector") == 1
    assert scraped.value("oricf_gateway_endpoint_recoveries_total", endpoint="detector") == 0
    active = {(s.labels["role"], s.labels["address"]): s.value
              for s in scraped.find("oricf_gateway_endpoint_active", endpoint="detector")}
    assert active == {("primary", primary): 0, ("fallback", fallback): 1}


def test_metrics_are_off_without_the_key() -> None:
    config = parse_pipeline({"endpoints": {"detector": {"address": "127.0.0.1:1"}},
                             "routes": {"r": {"input": {"url": "x.mp4"}, "call": DETECT,
                                              "outputs": [{"product": "p",
                                                           "from": "detections"}]}}},
                            "no metrics")
    p = Pipeline(config, Emitter())
    p.start()
    p.stop()
    assert config.metrics is None and p.metrics_server is None


def test_oricf_gateway_metrics_listen(detector: RunningService) -> None:
    metrics = f"127.0.0.1:{free_port()}"
    with oricf_process(
            "gateway", "--config", str(config_dir() / "pipelines" / "people_video.yaml"),
            "--set", f"endpoints.detector.address={detector.address}",
            "--set", f"routes.people.input.url={video_path()}",
            "--set", "routes.people.input.loop=true",
            "--metrics-listen", metrics) as gateway:
        scraped = wait_for_handled(f"http://{metrics}/metrics", gateway)
        gateway.send_signal(signal.SIGTERM)
        assert gateway.wait(30) == 0
    assert scraped.value("oricf_gateway_endpoint_active", endpoint="detector",
                         role="primary") == 1
    assert scraped.value("oricf_gateway_route_latency_seconds_count", route="people") >= 1


def test_the_ros_node_serves_them_with_the_frames_dds_replaced(ros_context: Context) -> None:
    frame = video_frames([0])[0]
    address = f"127.0.0.1:{free_port()}"
    # The detector in its own process, as in test_dds_people's burst: in this one it would
    # compete with the burst of publishes for the interpreter.
    with oricf_process("serve", "detector", "--listen", address) as detector:
        wait_serving(address, timeout=120, process=detector)
        config = people_qa({"metrics": {"listen": "127.0.0.1:0"}}, detector=address)
        with running_gateway(config, ros_context) as (gw, probe):
            for _ in range(30):  # faster than the detector: frames arrive while it is busy
                probe.publish_frame(frame)
                time.sleep(0.005)
            time.sleep(1.0)  # every frame delivered
            assert gw.pipeline.idle(10)
            scraped = read(gw.pipeline)
            stats = gw.pipeline.workers["people"].stats
    value = scraped.value
    replaced = value("oricf_gateway_route_inputs_replaced_total", route="people")
    assert replaced == stats.dropped >= 1
    assert value("oricf_gateway_route_inputs_received_total", route="people") == stats.received
    handled = sum(s.value for s in scraped.find("oricf_gateway_route_inputs_handled_total",
                                                 route="people"))
    assert handled == stats.handled and stats.received == replaced + handled


def wait_for_handled(url: str, process: Any) -> Scrape:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert process.poll() is None, process.stdout.read()
        try:
            scraped = scrape(url)
        except OSError:  # not listening yet
            time.sleep(0.2)
            continue
        if scraped.value("oricf_gateway_route_inputs_handled_total", route="people",
                         outcome="ok") >= 1:
            return scraped
        time.sleep(0.2)
    raise AssertionError(f"no input handled ok at {url} within 60 s")

