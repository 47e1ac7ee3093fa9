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
