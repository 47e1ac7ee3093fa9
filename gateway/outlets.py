"""Where a pipeline's outputs go: the pipeline's emitter, sending each output to the sink of its
key (oricf.gateway.sinks, found through components.SINKS), data products excepted (the
pipeline keeps those). Owns the pipeline's text channels and its sinks; `speaking` is the
pipeline's (oricf.gateway.speaking)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oricf.gateway.channels.server import Channels
from oricf.gateway.components import SINKS, ComponentContext, Emitter, Sink
from oricf.gateway.config import OutputConfig, PipelineConfig
from oricf.gateway.speaking import Speaking
from oricf.gateway.values import Record


class Outlets(Emitter):
    """The pipeline's sinks, one per output key its routes use, opened now (a speaker that
    is not there fails here). Topic outputs, the pipeline's ROS outputs, go to `ros`: the ROS
    node's publishers (oricf.gateway.ros.publishers.TopicPublishers), or without ROS, in a
    replay, the recording (oricf.gateway.recording.recorder.TopicOutputs); a topic output
    without it is an error when it is sent."""

    def __init__(self, config: PipelineConfig, ros: Emitter | None = None,
                 speaking: Speaking | None = None) -> None:
        self.ros = ros
        self.speaking = speaking or Speaking()
        self.channels = Channels(config.channels)
        context = ComponentContext(config, self.channels, self.speaking, ros)
        used = {output.sink for route in config.routes.values() for output in route.outputs}
        self.sinks: dict[str, Sink] = {}
        try:
            for key in used:
                opener = SINKS[key].open
                if opener is not None:
                    self.sinks[key] = opener(context)
        except BaseException:
            self.close()
            raise

    @property
    def speakers(self) -> Mapping[str, Any]:
        """The speakers the sinks play on, by device (for /metrics and tests)."""
        return {device: speaker for sink in self.sinks.values()
                for device, speaker in sink.speakers.items()}

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sinks[output.sink].send(output, value, record)

    def start(self) -> None:
        """Binds every channel now, so a port in use fails the start, not a route."""
        self.channels.open_all()

    def close(self) -> None:
        for sink in self.sinks.values():
            sink.close()
        self.channels.close()
