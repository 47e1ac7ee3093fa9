"""Route outputs that are not ROS topics or data products, by the output's sink key:
`jsonl` JSON lines (jsonl.py), `text` lines on standard output or a text channel (text.py),
`frames` image and video files (frames.py)."""

from __future__ import annotations

from typing import Any

from oricf.gateway.config import OutputConfig, PipelineConfig
from oricf.gateway.route import Emit
from oricf.gateway.sinks.frames import FrameFiles
from oricf.gateway.sinks.jsonl import JsonLines
from oricf.gateway.sinks.text import TextLines
from oricf.gateway.text_channels import Channels
from oricf.gateway.values import Record


class Outlets:
    """Where a pipeline's outputs go (data products excepted: the pipeline keeps those).
    Topic outputs go to `topics`: the ROS node's publishers (oricf.gateway.ros.publishers),
    or a recording when replaying without ROS. Owns the pipeline's text channels."""

    def __init__(self, config: PipelineConfig, topics: Emit | None = None) -> None:
        self.topics = topics
        self.channels = Channels(config.channels)
        self.jsonl = JsonLines()
        self.text = TextLines(self.channels)
        self.frames = FrameFiles()
        self._fps = {name: route.input.fps for name, route in config.routes.items()}

    def __call__(self, output: OutputConfig, value: Any, record: Record) -> None:
        route = str(record.get("route", ""))
        if output.jsonl is not None:
            self.jsonl.write(route, output, value)
        elif output.text is not None:
            self.text.write(output, value, record)
        elif output.frames is not None:
            self.frames.write(route, output, value, self._fps.get(route))
        elif self.topics is not None:
            self.topics(output, value, record)
        else:
            raise RuntimeError(f"output topic {output.topic} needs the ROS node")

    def start(self) -> None:
        """Binds every channel now, so a port in use fails the start, not a route."""
        self.channels.open_all()

    def close(self) -> None:
        self.jsonl.close()
        self.frames.close()
        self.channels.close()
