"""The routing core without ROS, against a real detector service."""

from __future__ import annotations

import logging
import time
from typing import Any

import pytest

from oricf.config import deep_merge
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig, PipelineConfig, parse_pipeline
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame, Record
from tests.support.data import video_frames
from tests.support.processes import free_port
from tests.support.services import RunningService, running_service

FRAMES = [0, 400, 440]


def pipeline_config(address: str, change: dict[str, Any] | None = None) -> PipelineConfig:
    data = {
        "endpoints": {"detector": {"address": address}},
        "routes": {"people": {
            "input": {"topic": "camera/image_raw", "type": "sensor_msgs/Image"},
            "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
            "post": [{"map_labels": {"person": "human"}},
                     {"filter": {"min_score": 0.5}},
                     {"count": {"label": "human", "into": "humans"}},
                     {"template": {"text": "{humans} people in view", "into": "summary"}}],
            "outputs": [{"topic": "/human_counter", "type": "std_msgs/Int32", "from": "humans"},
                        {"topic": "/summary", "type": "std_msgs/String", "from": "summary"},
                        {"product": "people_count", "from": "humans"}]}}}
    return parse_pipeline(deep_merge(data, change or {}), "test pipeline")


class Outputs(Emitter):
    def __init__(self) -> None:
        self.sent: list[tuple[str, Any]] = []

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sent.append((str(output.topic), value))


def run_frames(config: PipelineConfig, indices: list[int]) -> tuple[Pipeline, Outputs]:
    outputs = Outputs()
    pipeline = Pipeline(config, outputs)
    pipeline.start()
    for frame in video_frames(indices):
        loaded = Frame.from_pixels(frame)
        pipeline.submit("people", lambda f=loaded: {"image": f})
        assert pipeline.idle(10)
    pipeline.stop()
    return pipeline, outputs


def test_the_routes_see_the_speaking_state_of_the_outlets_that_play_speech() -> None:
    """Muting and barge-in read the state the speakers write: every way of starting a
    pipeline from its outlets shares it (oricf mcp --config once made a second one)."""
    config = pipeline_config("127.0.0.1:1")
    outlets = Outlets(config)
    try:
        assert Pipeline(config, outlets).speaking is outlets.speaking
        assert Pipeline(config, Emitter()).speaking is not outlets.speaking
    finally:
        outlets.close()


def test_route_calls_post_processes_and_sends(detector: RunningService) -> None:
    pipeline, outputs = run_frames(pipeline_config(detector.address), FRAMES)
    # frame 0: four detections, one of them (the post) under 0.5 after filtering
    assert outputs.sent[:2] == [("/human_counter", 4), ("/summary", "4 people in view")]
    counts = [v for topic, v in outputs.sent if topic == "/human_counter"]
    assert len(counts) == 3 and all(3 <= c <= 6 for c in counts)
    reading = pipeline.products.read("people_count")
    assert reading is not None and reading.value == counts[-1] and not reading.stale


def test_jpeg_transport_counts_like_raw(detector: RunningService) -> None:
    jpeg = {"endpoints": {"detector": {"image": {"transport": "jpeg", "jpeg_quality": 85}}}}
    _, raw_out = run_frames(pipeline_config(detector.address), FRAMES)
    _, jpeg_out = run_frames(pipeline_config(detector.address, jpeg), FRAMES)
    raw_counts = [v for t, v in raw_out.sent if t == "/human_counter"]
    jpeg_counts = [v for t, v in jpeg_out.sent if t == "/human_counter"]
    assert all(abs(a - b) <= 1 for a, b in zip(raw_counts, jpeg_counts, strict=True))


def test_a_dead_service_is_logged_throttled_and_the_route_recovers(
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    port = free_port()
    config = pipeline_config(f"127.0.0.1:{port}")
    outputs = Outputs()
    pipeline = Pipeline(config, outputs)
    pipeline.start()
    frame = Frame.from_pixels(video_frames([0])[0])
    for _ in range(5):
        pipeline.submit("people", lambda: {"image": frame})
        assert pipeline.idle(10)
    route = pipeline.routes["people"]
    assert route.stats.call_errors == 5 and route.stats.errors == {"UNAVAILABLE": 5}
    failures = [r for r in caplog.records if "Detect call to detector" in r.getMessage()]
    assert len(failures) == 1 and failures[0].levelno == logging.ERROR  # throttled
    assert "UNAVAILABLE" in failures[0].getMessage()
    with running_service("detector", {"server": {"listen": f"127.0.0.1:{port}"}}):
        deadline = time.monotonic() + 10
        while not outputs.sent and time.monotonic() < deadline:
            pipeline.submit("people", lambda: {"image": frame})
            assert pipeline.idle(10)
            time.sleep(0.1)  # the channel reconnects within its backoff (about a second)
    pipeline.stop()
    assert outputs.sent[0] == ("/human_counter", 4)
