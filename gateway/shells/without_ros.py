"""The gateway without ROS: for pipelines whose inputs and outputs are no ROS topics (video
URLs, microphones, text channels, data products, JSON lines). rclpy is never imported, so it
runs where ROS is not installed (an agent's topic targets import it when first used). Stops
on SIGTERM/SIGINT, or when every input has ended.
"""

from __future__ import annotations

import logging
import threading

from oricf.gateway.config import PipelineConfig
from oricf.gateway.host.gateway import Gateway
from oricf.gateway.recording.recorder import TopicOutputs
from oricf.gateway.recording.replay import Replay
from oricf.gateway.ros.commands import RosSender
from oricf.signals import stop_on_signals

log = logging.getLogger(__name__)

DRAIN_S = 10.0  # what the routes hold when the inputs end is finished, up to this long


def run(config: PipelineConfig, replay: Replay | None = None) -> int:
    """Runs until stopped or every input has ended. With `replay` (--replay), topic inputs
    come from a recording and topic outputs go to its recorder or standard output; the exit
    code is then the replay's."""
    gateway = Gateway(config, ros_sender=RosSender)
    ended: set[str] = set()
    lock = threading.Lock()
    with stop_on_signals() as stop:
        def on_end(route: str) -> None:
            with lock:
                ended.add(route)
                if ended >= {source.route for source in gateway.inputs}:
                    stop.set()

        gateway.configure(None if replay is None else TopicOutputs(replay.recorder), on_end)
        try:
            if replay is not None:
                gateway.add_inputs(replay.sources(gateway.pipeline, on_end))
            gateway.activate()
            log.info("gateway (no ROS): %d routes, sources: %s", len(config.routes),
                     ", ".join(f"{s.route} ({config.routes[s.route].input.source})"
                               for s in gateway.inputs) or "none")
            while not stop.wait(0.5):
                pass
            gateway.deactivate(drain_s=DRAIN_S)
        finally:
            gateway.cleanup()
    if replay is not None:
        return replay.close()
    return 0
