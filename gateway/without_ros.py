"""The gateway without ROS: for pipelines whose inputs and outputs are no ROS topics (video
URLs, microphones, text channels, data products, JSON lines). rclpy is never imported, so it
runs where ROS is not installed. Stops on SIGTERM/SIGINT, or when every source has ended.
"""

from __future__ import annotations

import logging
import threading

from oricf.gateway.config import PipelineConfig
from oricf.gateway.inputs import pipeline_sources
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.recorder import TopicOutputs
from oricf.gateway.recording.replay import Replay
from oricf.gateway.surfaces import serve_gateway_control
from oricf.signals import stop_on_signals

log = logging.getLogger(__name__)


def run(config: PipelineConfig, replay: Replay | None = None) -> int:
    """Runs until stopped or every source has ended. With `replay` (--replay), topic inputs
    come from a recording and topic outputs go to its recorder or standard output; the exit
    code is then the replay's."""
    outlets = Outlets(config, None if replay is None else TopicOutputs(replay.recorder))
    pipeline = Pipeline(config, outlets)
    ended: set[str] = set()
    lock = threading.Lock()
    with stop_on_signals() as stop:
        def on_end(route: str) -> None:
            with lock:
                ended.add(route)
                if ended >= {s.route for s in sources}:
                    stop.set()

        sources = pipeline_sources(pipeline, outlets.channels, on_end)
        if replay is not None:
            sources += replay.sources(pipeline, on_end)
        outlets.start()
        pipeline.start()
        stop_control = serve_gateway_control(pipeline, outlets.channels)
        for source in sources:
            source.start()
        log.info("gateway (no ROS): %d routes, sources: %s", len(config.routes),
                 ", ".join(f"{s.route} ({config.routes[s.route].input.source})"
                           for s in sources) or "none")
        while not stop.wait(0.5):
            pass
        for source in sources:
            source.stop()
        pipeline.idle(10)
        stop_control()
        pipeline.stop()
    outlets.close()
    if replay is not None:
        return replay.close()
    return 0
