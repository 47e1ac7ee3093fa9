"""Real test data from the model store. Missing data fails loudly (run scripts/setup.sh)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from oricf.store import ModelStore


def data_file(name: str, file: str) -> Path:
    return ModelStore().path(name, file)


def image(file: str) -> Path:
    """A darknet sample photo: person.jpg, dog.jpg, horses.jpg, kite.jpg."""
    return data_file("darknet-images", file)


def video_path() -> Path:
    return data_file("vtest-video", "vtest.avi")


def video_frames(indices: list[int], size: tuple[int, int] | None = None) -> list[np.ndarray]:
    """BGR frames of vtest.avi at the given indices, optionally resized to (width, height)."""
    capture = cv2.VideoCapture(str(video_path()))
    frames = []
    try:
        for index in indices:
            capture.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, frame = capture.read()
            if not ok:
                raise RuntimeError(f"cannot read frame {index} of {video_path()}")
            frames.append(cv2.resize(frame, size) if size else frame)
    finally:
        capture.release()
    return frames


def text_crops() -> list[np.ndarray]:
    """Crops of printed text lines from OpenCV's sample page, four times as wide as high,
    upright (the text-direction classifier's input shape)."""
    page = cv2.imread(str(data_file("opencv-text-image", "imageTextN.png")))
    ink = (cv2.cvtColor(page, cv2.COLOR_BGR2GRAY) < 128).sum(axis=1)
    lines, start = [], None
    for y, count in enumerate(ink):
        if count and start is None:
            start = y
        elif not count and start is not None:
            lines.append((start, y))
            start = None
    crops = []
    for top, bottom in lines:
        height = bottom - top + 6
        y = max(0, top - 3)
        for x in range(10, page.shape[1] - 4 * height, 4 * height):
            crops.append(page[y:y + height, x:x + 4 * height])
    return crops
