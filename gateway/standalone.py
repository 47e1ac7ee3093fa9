"""The gateway without ROS: for pipelines whose inputs and outputs are no ROS topics (video
URLs, microphones, text channels, data products, JSON lines). rclpy is never imported, so it
runs where ROS is not installed. Stops on SIGTERM/SIGINT, or when every source has ended.
"""

from __future__ import annotations

import functools
import logging
import threading
from typing import TYPE_CHECKING

from oricf.gateway.config import PipelineConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.record import TopicOutputs
from oricf.gateway.sinks import Outlets
from oricf.gateway.sources import OnEnd, Source, Submit, make_sources
from oricf.signals import stop_on_signals

if TYPE_CHECKING:
    from oricf.gateway.sources.replay import Replay

log = logging.getLogger(__name__)


def pipeline_sources(pipeline: Pipeline, outlets: Outlets, on_end: OnEnd) -> list[Source]:
    """The pipeline's non-topic sources, each feeding its route."""
    submit: dict[str, Submit] = {name: functools.partial(pipeline.submit, name)
                                 for name in pipeline.config.routes}
    return make_sources(pipeline.config, submit, on_end, outlets.channels)


def run(config: PipelineConfig, replay: Replay | None = None) -> int:
    """Runs until stopped or every source has ended. With `replay` (--replay), topic inputs
    come from a recording and topic outputs go to its recorder or standard output; the exit
    code is then the replay's."""
    outlets = Outlets(config)
    pipeline = Pipeline(config, outlets if replay is None
                        else TopicOutputs(outlets, replay.recorder))
    ended: set[str] = set()
    lock = threading.Lock()
    with stop_on_signals() as stop:
        def on_end(route: str) -> None:
            with lock:
                ended.add(route)
                if ended >= {s.route for s in sources}:
                    stop.set()

        sources = pipeline_sources(pipeline, outlets, on_end)
        if replay is not None:
            sources += replay.sources(pipeline, on_end)
        outlets.start()
        pipeline.start()
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
        pipeline.stop()
    outlets.close()
    if replay is not None:
        return replay.close()
    return 0
