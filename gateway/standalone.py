"""The gateway without ROS: for pipelines whose inputs and outputs are no ROS topics (video
URLs, data products, JSON lines). rclpy is never imported, so it runs where ROS is not
installed. Stops on SIGTERM/SIGINT, or when every video input has ended.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from oricf.gateway.config import OutputConfig, PipelineConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sinks import JsonLines
from oricf.gateway.sources import VideoSource
from oricf.gateway.values import Record
from oricf.signals import stop_on_signals

log = logging.getLogger(__name__)


class Outlets:
    """Where a pipeline's non-product outputs go: JSON lines here; topics only in the node."""

    def __init__(self) -> None:
        self.jsonl = JsonLines()

    def __call__(self, output: OutputConfig, value: Any, record: Record) -> None:
        if output.jsonl is not None:
            self.jsonl.write(str(record.get("route", "")), output, value)
        else:
            raise RuntimeError(f"output topic {output.topic} needs the ROS node")


def video_sources(pipeline: Pipeline, on_end: Any) -> list[VideoSource]:
    return [VideoSource(name, route.input, _submitter(pipeline, name), on_end)
            for name, route in pipeline.config.routes.items() if route.input.url is not None]


def _submitter(pipeline: Pipeline, route: str) -> Any:
    return lambda load: pipeline.submit(route, load)


def run(config: PipelineConfig) -> int:
    outlets = Outlets()
    pipeline = Pipeline(config, outlets)
    ended: set[str] = set()
    lock = threading.Lock()
    with stop_on_signals() as stop:
        def on_end(route: str) -> None:
            with lock:
                ended.add(route)
                if ended >= {s.route for s in sources}:
                    stop.set()

        sources = video_sources(pipeline, on_end)
        pipeline.start()
        for source in sources:
            source.start()
        log.info("gateway (no ROS): %d routes, %d video inputs", len(config.routes),
                 len(sources))
        while not stop.wait(0.5):
            pass
        for source in sources:
            source.stop()
        pipeline.idle(10)
        pipeline.stop()
    outlets.jsonl.close()
    return 0
