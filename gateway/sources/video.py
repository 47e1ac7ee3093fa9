"""Video inputs (`input: {url: ..., fps: 5}`): frames from a file, an RTSP or HTTP stream,
or a V4L2 device, the newest frame winning. This module declares the input (its settings
and COMPONENT); what opens, reads and reconnects the video is video_source.py (FFmpeg
through OpenCV, or mjpeg.py for an HTTP Motion JPEG stream), imported when a pipeline opens
a video input, so that loading the pipeline schema loads no stream reader or decoder.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import ComponentContext
from oricf.gateway.sources.base import OnEnd, Source, SourceKind, Submit


class VideoInput(Schema):
    url: str | None = Field(
        None, description="a video: a file, rtsp://, http(s)://, or a device /dev/videoN")
    fps: float | None = Field(None, gt=0, le=240, description="url: at most this many frames/s")
    loop: bool = Field(False, description="url: a file starts again at its end (else the "
                                          "route ends)")


def stray(config: Any) -> str | None:
    return "fps, loop: only with url" if config.fps is not None or config.loop else None


def open_source(route: str, config: Any, submit: Submit, on_end: OnEnd,
                context: ComponentContext) -> Source:
    from oricf.gateway.sources.video_source import VideoSource  # a pipeline opens one

    return VideoSource(route, config, submit, on_end)


COMPONENT = SourceKind("url", VideoInput, lambda config: "image", open_source, stray=stray,
                       latest=lambda config: True, rank=2)
