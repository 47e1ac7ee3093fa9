"""Route outputs other than ROS topics and data products, by the output's sink key:
`jsonl` JSON lines (jsonl.py), `text` lines on standard output or a text channel (text.py),
`frames` image and video files (frames.py), `audio` speech on a speaker (speaker.py), `wav`
speech into WAV files (wav.py). `Outlets` hands each output to its sink, and each topic
output, a ROS output, to the ROS side."""

from __future__ import annotations

from typing import Any, TypeAlias

from oricf.errors import ConfigError
from oricf.gateway.config import OutputConfig, PipelineConfig
from oricf.gateway.route import Emit
from oricf.gateway.sinks.frames import FrameFiles
from oricf.gateway.sinks.jsonl import JsonLines
from oricf.gateway.sinks.text import TextLines
from oricf.gateway.sinks.wav import WavFiles
from oricf.gateway.speaking import Speaking
from oricf.gateway.text_channels import Channels
from oricf.gateway.values import Record

# Where topic outputs, the pipeline's ROS outputs, go: the ROS node's publishers
# (oricf.gateway.ros.publishers.TopicPublishers), or without ROS, in a replay, the
# recording (oricf.gateway.recording.recorder.TopicOutputs); each converts the value to the
# topic's message through the topic codec (oricf.gateway.topics.codec).
RosOutputs: TypeAlias = Emit


class Outlets:
    """Where a pipeline's outputs go (data products excepted: the pipeline keeps those): an
    output with a sink key to that sink, a topic output to `ros` (RosOutputs; a topic output
    without one is an error). Owns the pipeline's text channels and speakers; `speaking` is
    the pipeline's (oricf.gateway.speaking)."""

    def __init__(self, config: PipelineConfig, ros: RosOutputs | None = None,
                 speaking: Speaking | None = None) -> None:
        self.ros = ros
        self.speaking = speaking or Speaking()
        self.speakers = speakers(config, self.speaking)
        self.wav = WavFiles()
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
        elif output.audio is not None:
            self.speakers[output.audio.device].play(value)
        elif output.wav is not None:
            self.wav.write(output.wav, value)
        elif self.ros is not None:
            self.ros(output, value, record)
        else:
            raise RuntimeError(f"output topic {output.topic} needs the ROS node")

    def start(self) -> None:
        """Binds every channel now, so a port in use fails the start, not a route."""
        self.channels.open_all()

    def close(self) -> None:
        for speaker in self.speakers.values():
            speaker.close()
        self.wav.close()
        self.jsonl.close()
        self.frames.close()
        self.channels.close()


def speakers(config: PipelineConfig, speaking: Speaking) -> dict[str, Any]:
    """A Speaker per device that `audio:` outputs name, opened (checked) now: a device that
    is not there is a ConfigError naming the file and the key."""
    found: dict[str, Any] = {}
    for name, route in config.routes.items():
        for i, output in enumerate(route.outputs):
            if output.audio is None or output.audio.device in found:
                continue
            from oricf.gateway.sinks.speaker import Speaker  # PortAudio only when used

            try:
                found[output.audio.device] = Speaker(output.audio, speaking)
            except ConfigError as exc:
                for speaker in found.values():
                    speaker.close()
                raise ConfigError(f"{config.origin}: routes.{name}.outputs[{i}].audio.device: "
                                  f"{exc}") from None
    return found
