"""Detection output decoders, chosen by name in a declaration (`decoder: yolox`).

Each turns the model's raw output into candidate boxes (x_min, y_min, x_max, y_max in
network-input pixels), scores and class ids, keeping candidates at or above min_score and,
when class_ids is given, considering those classes only. NMS and the mapping back to image
pixels are shared (oricf.models.detection).

    yolox   [1, N, 5 + classes]: cx, cy, log w, log h relative to grid cells of the strides,
            objectness, class probabilities; score = objectness * class probability
    yolov8  [1, 4 + classes, N]: cx, cy, w, h in pixels, class scores (Ultralytics export:
            YOLOv8, YOLO11)
    ssd     [1, 1, N, 7]: image id, class id, score, corners normalised to 0-1 (OpenVINO
            Model Zoo detectors, TensorFlow Object Detection API exports)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeAlias

import numpy as np

from oricf.errors import InvalidInput

Candidates: TypeAlias = tuple[np.ndarray, np.ndarray, np.ndarray]  # boxes, scores, class ids
Decoder: TypeAlias = Callable[[np.ndarray, float, "np.ndarray | None"], Candidates]


def _best_class(class_scores: np.ndarray, class_ids: np.ndarray | None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per row: the best score and its class id, among class_ids if given."""
    if class_ids is not None:
        class_scores = class_scores[:, class_ids]
    best = class_scores.argmax(axis=1)
    scores = class_scores[np.arange(len(class_scores)), best]
    return scores, best if class_ids is None else class_ids[best]


def _corners(centres: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    return np.concatenate((centres - sizes / 2, centres + sizes / 2), axis=1)


def _rows(output: np.ndarray, width: int, name: str) -> np.ndarray:
    if output.ndim != 3 or output.shape[0] != 1 or output.shape[2] != width:
        raise InvalidInput(f"{name} decoder: output shape {list(output.shape)} is not "
                           f"[1, N, {width}] (the labels give {width - 5} classes)")
    return output[0].astype(np.float32, copy=False)


def yolox(size: tuple[int, int], strides: Sequence[int], classes: int) -> Decoder:
    cells, cell_strides = [], []
    for stride in strides:
        nx, ny = size[0] // stride, size[1] // stride
        ys, xs = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        cells.append(np.stack((xs, ys), axis=-1).reshape(-1, 2))
        cell_strides.append(np.full((nx * ny, 1), stride))
    grid = np.concatenate(cells).astype(np.float32)
    grid_strides = np.concatenate(cell_strides).astype(np.float32)

    def decode(output: np.ndarray, min_score: float, class_ids: np.ndarray | None
               ) -> Candidates:
        rows = _rows(output, 5 + classes, "yolox")
        if len(rows) != len(grid):
            raise InvalidInput(f"yolox decoder: {len(rows)} rows, but strides "
                               f"{list(strides)} at {size[0]}x{size[1]} give {len(grid)}")
        scores, labels = _best_class(rows[:, 5:5 + classes] * rows[:, 4:5], class_ids)
        keep = scores >= min_score
        centres = (rows[keep, :2] + grid[keep]) * grid_strides[keep]
        sizes = np.exp(rows[keep, 2:4]) * grid_strides[keep]
        return _corners(centres, sizes), scores[keep], labels[keep]

    return decode


def yolov8(size: tuple[int, int], strides: Sequence[int], classes: int) -> Decoder:
    def decode(output: np.ndarray, min_score: float, class_ids: np.ndarray | None
               ) -> Candidates:
        if output.ndim != 3 or output.shape[0] != 1 or output.shape[1] != 4 + classes:
            raise InvalidInput(f"yolov8 decoder: output shape {list(output.shape)} is not "
                               f"[1, 4 + {classes}, N] (the labels give {classes} classes)")
        rows = output[0].T.astype(np.float32, copy=False)
        scores, labels = _best_class(rows[:, 4:4 + classes], class_ids)
        keep = scores >= min_score
        return _corners(rows[keep, :2], rows[keep, 2:4]), scores[keep], labels[keep]

    return decode


def ssd(size: tuple[int, int], strides: Sequence[int], classes: int) -> Decoder:
    scale = np.array([size[0], size[1], size[0], size[1]], dtype=np.float32)

    def decode(output: np.ndarray, min_score: float, class_ids: np.ndarray | None
               ) -> Candidates:
        if output.ndim != 4 or output.shape[:2] != (1, 1) or output.shape[3] != 7:
            raise InvalidInput(f"ssd decoder: output shape {list(output.shape)} is not "
                               f"[1, 1, N, 7]")
        rows = output[0, 0].astype(np.float32, copy=False)
        rows = rows[rows[:, 0] >= 0]  # image id -1 ends the list
        labels = rows[:, 1].astype(np.int64)
        keep = (rows[:, 2] >= min_score) & (labels >= 0) & (labels < classes)
        if class_ids is not None:
            keep &= np.isin(labels, class_ids)
        return rows[keep, 3:7] * scale, rows[keep, 2], labels[keep]

    return decode


# name -> factory(network size (w, h), strides, number of classes) -> decoder
DECODERS: dict[str, Callable[[tuple[int, int], Sequence[int], int], Decoder]] = {
    "yolox": yolox,
    "yolov8": yolov8,
    "ssd": ssd,
}
