"""Images (e.g. `annotated`) to files: `frames: PATH` where PATH is

- a video file (.mp4, .avi, .mkv): frames appended, at `fps` (default 10), size fixed by
  the first frame (later frames of another size are scaled to it);
- an image file (.jpg, .jpeg, .png): the newest frame, replaced atomically, so a viewer or a
  web page always reads a whole image;
- anything else, a folder (made if missing): numbered JPEGs, ROUTE-000001.jpg, ...
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import ComponentContext, Sink, SinkKind
from oricf.gateway.values import Frame, Record

if TYPE_CHECKING:
    from oricf.gateway.config import OutputConfig

log = logging.getLogger(__name__)

VIDEO_CODECS = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "MJPG"}
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
DEFAULT_FPS = 10.0


class FrameFiles(Sink):
    """Every frames output of a pipeline; one writer per path."""

    def __init__(self, fps: dict[str, float | None] | None = None) -> None:
        self._fps = fps or {}  # route -> its input's frame rate (a video's frame rate)
        self._videos: dict[str, tuple[Any, tuple[int, int]]] = {}  # path -> writer, size
        self._numbers: dict[str, int] = {}
        self._lock = threading.Lock()

    def write(self, route: str, output: OutputConfig, value: Any, fps: float | None) -> None:
        assert output.frames is not None
        if not isinstance(value, Frame):
            raise TypeError(f"frames: {output.source} is not an image")
        pixels = value.pixels()
        path = Path(output.frames).expanduser()
        with self._lock:
            if path.suffix.lower() in VIDEO_CODECS:
                self._append(path, pixels, fps or DEFAULT_FPS)
            elif path.suffix.lower() in IMAGE_SUFFIXES:
                _replace_image(path, pixels)
            else:
                key = f"{path}/{route}"
                self._numbers[key] = self._numbers.get(key, 0) + 1
                path.mkdir(parents=True, exist_ok=True)
                _write_image(path / f"{route}-{self._numbers[key]:06d}.jpg", pixels)

    def _append(self, path: Path, pixels: Any, fps: float) -> None:
        import cv2

        if str(path) not in self._videos:
            size = (pixels.shape[1], pixels.shape[0])
            path.parent.mkdir(parents=True, exist_ok=True)
            fourcc = cv2.VideoWriter.fourcc(*VIDEO_CODECS[path.suffix.lower()])
            opened = cv2.VideoWriter(str(path), fourcc, fps, size)
            if not opened.isOpened():
                raise OSError(f"frames: cannot write the video {path}")
            self._videos[str(path)] = (opened, size)
            log.info("frames: writing %s (%dx%d, %g fps)", path, *size, fps)
        writer, size = self._videos[str(path)]
        if (pixels.shape[1], pixels.shape[0]) != size:
            pixels = cv2.resize(pixels, size)
        writer.write(pixels)

    def send(self, output: OutputConfig, value: Any, record: Record) -> None:
        route = str(record.get("route", ""))
        self.write(route, output, value, self._fps.get(route))

    def close(self) -> None:
        with self._lock:
            for writer, _ in self._videos.values():
                writer.release()
            self._videos.clear()


def _write_image(path: Path, pixels: Any) -> None:
    import cv2

    if not cv2.imwrite(str(path), pixels):
        raise OSError(f"frames: cannot write {path}")


def _replace_image(path: Path, pixels: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")
    _write_image(partial, pixels)
    os.replace(partial, path)


class FramesOutput(Schema):
    frames: str | None = Field(
        None, description="images to a folder (numbered JPEGs), a .jpg/.png file (the newest "
                          "frame), or a video file (.mp4, .avi, .mkv)")


def open_files(context: ComponentContext) -> Sink:
    return FrameFiles({name: getattr(route.input, "fps", None)
                       for name, route in context.config.routes.items()})


COMPONENT = SinkKind("frames", FramesOutput, open_files, rank=4)
