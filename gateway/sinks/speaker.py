"""Speech outputs (`audio: {device: ...}`): each piece of speech a route makes, played in
order on an audio output device. This module declares the output (its settings and
COMPONENT); what plays it is speaker_sink.py (PortAudio, through speaker_device.py),
imported when a pipeline opens its speakers, so that loading the pipeline schema loads no
audio device.
"""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import ComponentContext, Sink, SinkKind


class SpeakerConfig(Schema):
    """A speaker: an audio output device that plays speech."""

    device: str = Field("default", description="'default', an index, a PortAudio name, or "
                                               "a PulseAudio sink")


class SpeakerOutput(Schema):
    audio: SpeakerConfig | None = Field(None, description="speech played on an audio device")


def open_speakers(context: ComponentContext) -> Sink:
    from oricf.gateway.sinks.speaker_sink import Speakers  # a pipeline opens them

    return Speakers(context)


COMPONENT = SinkKind("audio", SpeakerOutput, open_speakers, rank=5)
