"""YOLOX on onnxruntime: letterbox preprocessing, vectorised decoding and NMS.

The exported YOLOX-Nano takes a BGR image letterboxed to a square (pad right and bottom
with grey 114), values 0-255, and returns one row per grid cell of strides 8, 16 and 32:
4 raw box values, objectness and 80 class probabilities (sigmoid already applied).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from oricf.errors import ConfigError, NotReady
from oricf.services.detector.coco import COCO_LABELS
from oricf.services.runtime import ModelInfo

log = logging.getLogger(__name__)

STRIDES = (8, 16, 32)
PAD_VALUE = 114


@dataclass
class RawDetections:
    """Detections in input-image pixels, best score first."""

    boxes: np.ndarray      # (n, 4) float32: x_min, y_min, x_max, y_max
    scores: np.ndarray     # (n,) float32
    class_ids: np.ndarray  # (n,) int64
    timings_ms: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class PreparedImage:
    """A letterboxed network input and what it takes to map boxes back."""

    blob: np.ndarray
    scale: float
    width: int
    height: int
    preprocess_ms: float


@dataclass(frozen=True)
class YoloxSettings:
    path: Path
    catalog_name: str
    sha256: str
    license: str
    providers: tuple[str, ...]
    threads: int
    spin: bool
    input_size: int
    nms_iou: float
    max_detections: int


def letterbox(image: np.ndarray, size: int) -> tuple[np.ndarray, float]:
    """Resize keeping the aspect ratio, pad to size x size; returns the NCHW blob and scale."""
    height, width = image.shape[:2]
    scale = min(size / height, size / width)
    new_w, new_h = max(1, int(width * scale)), max(1, int(height * scale))
    canvas = np.full((size, size, 3), PAD_VALUE, dtype=np.uint8)
    canvas[:new_h, :new_w] = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    blob = np.ascontiguousarray(canvas.transpose(2, 0, 1)[np.newaxis], dtype=np.float32)
    return blob, scale


def make_grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (n, 2) and strides (n, 1) in the order of the model's output rows."""
    cells, strides = [], []
    for stride in STRIDES:
        n = size // stride
        ys, xs = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        cells.append(np.stack((xs, ys), axis=-1).reshape(-1, 2))
        strides.append(np.full((n * n, 1), stride))
    return np.concatenate(cells).astype(np.float32), np.concatenate(strides).astype(np.float32)


def nms(boxes: np.ndarray, scores: np.ndarray, class_ids: np.ndarray, iou_threshold: float,
        limit: int) -> np.ndarray:
    """Greedy per-class non-maximum suppression; returns kept indices, best first."""
    if len(boxes) == 0:
        return np.empty(0, dtype=np.int64)
    # Shift each class to its own region so one pass never suppresses across classes.
    shifted = boxes + (class_ids.astype(np.float32) * (boxes.max() + 1.0))[:, None]
    areas = (shifted[:, 2] - shifted[:, 0]) * (shifted[:, 3] - shifted[:, 1])
    order = scores.argsort()[::-1]
    keep: list[int] = []
    while order.size and len(keep) < limit:
        best, rest = order[0], order[1:]
        keep.append(int(best))
        x1 = np.maximum(shifted[best, 0], shifted[rest, 0])
        y1 = np.maximum(shifted[best, 1], shifted[rest, 1])
        x2 = np.minimum(shifted[best, 2], shifted[rest, 2])
        y2 = np.minimum(shifted[best, 3], shifted[rest, 3])
        inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
        iou = inter / (areas[best] + areas[rest] - inter + 1e-9)
        order = rest[iou <= iou_threshold]
    return np.array(keep, dtype=np.int64)


class YoloxDetector:
    """The detector model: load(), infer(), close(), info(). Knows nothing of gRPC."""

    def __init__(self, settings: YoloxSettings) -> None:
        self.settings = settings
        self._session: Any = None
        self._input_name = ""
        self._cells, self._strides = make_grid(settings.input_size)
        self._runtime = "onnxruntime"
        self._providers: list[str] = []

    def load(self) -> None:
        import onnxruntime as ort

        available = ort.get_available_providers()
        missing = [p for p in self.settings.providers if p not in available]
        if missing:
            raise ConfigError(f"model.providers: {', '.join(missing)} not available in this "
                              f"onnxruntime build (available: {', '.join(available)})")
        options = ort.SessionOptions()
        options.intra_op_num_threads = self.settings.threads
        options.inter_op_num_threads = 1
        # Spinning threads burn a core between frames (measured: 49 ms of CPU per 640x480
        # frame at 10 fps with 2 threads, against 11 ms without).
        options.add_session_config_entry("session.intra_op.allow_spinning",
                                         "1" if self.settings.spin else "0")
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        session = ort.InferenceSession(str(self.settings.path), options,
                                       providers=list(self.settings.providers))
        self._input_name = session.get_inputs()[0].name
        self._runtime = f"onnxruntime {ort.__version__}"
        self._providers = session.get_providers()
        size = self.settings.input_size
        session.run(None, {self._input_name: np.zeros((1, 3, size, size), np.float32)})  # warm-up
        self._session = session

    def close(self) -> None:
        self._session = None

    def info(self) -> ModelInfo:
        s = self.settings
        return ModelInfo(
            model=s.catalog_name, runtime=self._runtime, providers=self._providers,
            license=s.license, sha256=s.sha256, labels=list(COCO_LABELS),
            parameters={"input_size": str(s.input_size), "threads": str(s.threads),
                        "spin": str(s.spin).lower(),
                        "nms_iou": str(s.nms_iou)})

    def infer(self, image: np.ndarray, min_score: float,
              class_ids: np.ndarray | None = None) -> RawDetections:
        """Detects objects in a BGR image; class_ids restricts the classes considered."""
        return self.detect(self.prepare(image), min_score, class_ids)

    def prepare(self, image: np.ndarray) -> PreparedImage:
        """The network input for a BGR image. Separate from detect() so that a stream can
        prepare the next frame while this one is in the network."""
        started = time.perf_counter()
        blob, scale = letterbox(image, self.settings.input_size)
        return PreparedImage(blob, scale, image.shape[1], image.shape[0],
                             (time.perf_counter() - started) * 1e3)

    def detect(self, prepared: PreparedImage, min_score: float,
               class_ids: np.ndarray | None = None) -> RawDetections:
        session = self._session
        if session is None:
            raise NotReady("the detector model is not loaded")
        t0 = time.perf_counter()
        rows = session.run(None, {self._input_name: prepared.blob})[0][0]
        t1 = time.perf_counter()
        result = self._decode(rows, prepared.scale, prepared.width, prepared.height, min_score,
                              class_ids)
        result.timings_ms = {"preprocess_ms": prepared.preprocess_ms,
                             "inference_ms": (t1 - t0) * 1e3,
                             "postprocess_ms": (time.perf_counter() - t1) * 1e3}
        return result

    def _decode(self, rows: np.ndarray, scale: float, width: int, height: int,
                min_score: float, class_ids: np.ndarray | None) -> RawDetections:
        class_probs = rows[:, 5:] if class_ids is None else rows[:, 5:][:, class_ids]
        scores_per_class = class_probs * rows[:, 4:5]
        best = scores_per_class.argmax(axis=1)
        scores = scores_per_class[np.arange(len(rows)), best]
        keep = scores >= min_score
        centres = (rows[keep, :2] + self._cells[keep]) * self._strides[keep]
        sizes = np.exp(rows[keep, 2:4]) * self._strides[keep]
        boxes = np.concatenate((centres - sizes / 2, centres + sizes / 2), axis=1) / scale
        np.clip(boxes, 0, [width, height, width, height], out=boxes)
        labels = best[keep] if class_ids is None else class_ids[best[keep]]
        kept = nms(boxes, scores[keep], labels, self.settings.nms_iou,
                   self.settings.max_detections)
        return RawDetections(boxes[kept].astype(np.float32), scores[keep][kept].astype(np.float32),
                             labels[kept].astype(np.int64))
