"""Decoded detections instead of a detection model's raw output tensor, when a request
asks: a few hundred bytes back instead of the network's output (1.2 MB for YOLOX-Nano).

The request names the task's output among its outputs with the parameter `decoded: true`,
and optionally `min_score` (double, else the declaration's) and `class_ids` (a string of
comma-separated class indices to keep). The response's tensor of that name is then FP32
[n, 6], one row per detection, best score first, after non-maximum suppression:

    x_min, y_min, x_max, y_max (image pixels), score, class id

It needs the image itself in the request (encoded or UINT8, services/models/images.py):
the boxes are mapped back to the image's pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from oricf.errors import InvalidInput
from oricf.models.declared import DeclaredModel
from oricf.models.heads import DetectionHead, Prepared
from oricf.models.wire import parameter_value
from oricf.oip import open_inference_grpc_pb2 as oip

DECODED = "decoded"
COLUMNS = ("x_min", "y_min", "x_max", "y_max", "score", "class_id")


@dataclass(frozen=True)
class DecodeAsk:
    output: str
    min_score: float | None
    class_ids: np.ndarray | None


def decode_ask(model: DeclaredModel,
               wanted: list[oip.ModelInferRequest.InferRequestedOutputTensor]
               ) -> DecodeAsk | None:
    """What the request asks to decode, None if nothing; refused for a model that is not a
    declared detection model."""
    # Looked up with `in` first: indexing a protobuf map adds the key to the request.
    asking = [o for o in wanted
              if DECODED in o.parameters and parameter_value(o.parameters[DECODED]) is True]
    if not asking:
        return None
    head = model.head
    if not isinstance(head, DetectionHead):
        raise InvalidInput(f"model {model.name}: decoded outputs need a declared detection "
                           f"model (task.kind: detection)")
    if len(asking) > 1:
        raise InvalidInput("decoded: asked of more than one output")
    output = asking[0]
    task_output = head.output or model.outputs[0].name
    if output.name != task_output:
        raise InvalidInput(f"decoded: output '{output.name[:64]}' is not the one the task "
                           f"decodes ('{task_output}')")
    return DecodeAsk(output.name, _min_score(output), _class_ids(output, len(head.labels)))


def _min_score(output: oip.ModelInferRequest.InferRequestedOutputTensor) -> float | None:
    if "min_score" not in output.parameters:
        return None
    value = parameter_value(output.parameters["min_score"])
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or math.isnan(value) or not 0 < value <= 1:
        raise InvalidInput("min_score: a number in (0, 1]")
    return float(value)


def _class_ids(output: oip.ModelInferRequest.InferRequestedOutputTensor, classes: int
               ) -> np.ndarray | None:
    if "class_ids" not in output.parameters:
        return None
    value = parameter_value(output.parameters["class_ids"])
    try:
        ids = sorted({int(part) for part in str(value).split(",") if part.strip()})
    except ValueError:
        raise InvalidInput("class_ids: comma-separated class indices, e.g. '0,2'") from None
    if not ids or ids[0] < 0 or ids[-1] >= classes:
        raise InvalidInput(f"class_ids: indices from 0 to {classes - 1}")
    return np.array(ids, np.int64)


def decoded(model: DeclaredModel, ask: DecodeAsk, outputs: dict[str, np.ndarray],
            prepared: Prepared | None) -> np.ndarray:
    if prepared is None:
        raise InvalidInput("decoded: send the image (encoded, or UINT8 [H, W, C]) rather than "
                           "the network's tensor, so that boxes can be given in its pixels")
    head = model.head
    assert isinstance(head, DetectionHead)
    found = head.decode(outputs, prepared, ask.min_score, ask.class_ids)
    rows = np.empty((len(found.scores), len(COLUMNS)), np.float32)
    rows[:, :4] = found.boxes
    rows[:, 4] = found.scores
    rows[:, 5] = found.class_ids
    return rows
