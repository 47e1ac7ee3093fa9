"""A declared task's pre- and post-processing, without the model itself.

The same head runs in the model service (around its own session) and in the gateway
(around a remote ModelInfer call), so a model's pre- and post-processing exist once:

    head.prepare(image)                  -> Prepared: input tensors and the image geometry
    head.decode(outputs, prepared, ...)  -> Detections (boxes in image pixels, after NMS)
                                            or Classes (top-k labels and scores)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from oricf.errors import InvalidInput
from oricf.models.declaration import (
    ClassificationTask,
    DetectionTask,
    ImageInput,
    ModelDeclaration,
)
from oricf.models.decoders import DECODERS
from oricf.models.image import Geometry, network_size, to_tensor
from oricf.models.policy_task import PolicyTask
from oricf.models.tensors import clip


@dataclass(frozen=True)
class Prepared:
    feeds: dict[str, np.ndarray]
    geometry: Geometry
    preprocess_ms: float


@dataclass
class Detections:
    """Detections in image pixels, best score first."""

    boxes: np.ndarray      # (n, 4) float32: x_min, y_min, x_max, y_max
    scores: np.ndarray     # (n,) float32
    class_ids: np.ndarray  # (n,) int64
    timings_ms: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Classes:
    """The top classes, best first."""

    class_ids: list[int]
    labels: list[str]
    scores: list[float]


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


class ImageHead:
    """Turns an image into the input tensor of the model's image input."""

    def __init__(self, image: ImageInput, input_name: str, input_shape: tuple[int, ...],
                 output: str | None, labels: list[str]) -> None:
        self.image = image
        self.input_name = input_name
        self.size = network_size(image, input_shape)
        self.output = output
        self.labels = labels

    def prepare(self, pixels: np.ndarray) -> Prepared:
        started = time.perf_counter()
        tensor, geo = to_tensor(pixels, self.image, self.size)
        return Prepared({self.input_name: tensor}, geo, (time.perf_counter() - started) * 1e3)

    def output_of(self, outputs: dict[str, np.ndarray]) -> np.ndarray:
        """The output this task reads: the declared one, else the first."""
        if self.output is None:
            return next(iter(outputs.values()))
        try:
            return outputs[self.output]
        except KeyError:
            raise InvalidInput(f"the model returned no output '{clip(self.output)}' "
                               f"(it returned: {', '.join(outputs)})") from None


class DetectionHead(ImageHead):
    def __init__(self, task: DetectionTask, input_name: str, input_shape: tuple[int, ...]
                 ) -> None:
        super().__init__(task.image, input_name, input_shape, task.output, task.label_list())
        self.task = task
        self._decode = DECODERS[task.decoder](self.size, task.strides, len(self.labels))

    def decode(self, outputs: dict[str, np.ndarray], prepared: Prepared,
               min_score: float | None = None, class_ids: np.ndarray | None = None
               ) -> Detections:
        """Boxes in image pixels after NMS; min_score defaults to the declared one."""
        started = time.perf_counter()
        score = self.task.min_score if min_score is None else min_score
        boxes, scores, labels = self._decode(self.output_of(outputs), score, class_ids)
        boxes = prepared.geometry.to_image(boxes)
        kept = nms(boxes, scores, labels, self.task.nms.iou, self.task.nms.max_detections)
        return Detections(boxes[kept], scores[kept].astype(np.float32),
                          labels[kept].astype(np.int64),
                          {"postprocess_ms": (time.perf_counter() - started) * 1e3})


class ClassificationHead(ImageHead):
    def __init__(self, task: ClassificationTask, input_name: str,
                 input_shape: tuple[int, ...]) -> None:
        super().__init__(task.image, input_name, input_shape, task.output, task.label_list())
        self.task = task

    def decode(self, outputs: dict[str, np.ndarray], prepared: Prepared | None = None,
               top_k: int | None = None) -> Classes:
        scores = np.asarray(self.output_of(outputs), dtype=np.float64).reshape(-1)
        if self.labels and len(scores) != len(self.labels):
            raise InvalidInput(f"the model gave {len(scores)} scores for "
                               f"{len(self.labels)} labels")
        if self.task.softmax:
            exp = np.exp(scores - scores.max())
            scores = exp / exp.sum()
        order = scores.argsort()[::-1][:top_k or self.task.top_k]
        return Classes([int(i) for i in order],
                       [self.labels[i] if self.labels else str(i) for i in order],
                       [float(scores[i]) for i in order])


Head = DetectionHead | ClassificationHead


def make_head(task: DetectionTask | ClassificationTask, input_name: str,
              input_shape: tuple[int, ...]) -> Head:
    if isinstance(task, DetectionTask):
        return DetectionHead(task, input_name, input_shape)
    return ClassificationHead(task, input_name, input_shape)


def declared_head(declaration: ModelDeclaration) -> Head:
    """The head from the declaration alone, for a caller without the model file (the
    gateway): the image input's name and size must then be declared. Raises ValueError."""
    task = declaration.task
    if task is None:
        raise ValueError(f"model {declaration.name} declares no task")
    if isinstance(task, PolicyTask):
        raise ValueError(f"model {declaration.name} is a policy: it has no image task")
    name = task.image.input or (declaration.inputs[0].name if declaration.inputs else None)
    if name is None:
        raise ValueError(f"model {declaration.name}: name its image input (task.image.input)")
    shape = next((tuple(i.shape) for i in declaration.inputs if i.name == name and i.shape),
                 ())
    return make_head(task, name, shape)
