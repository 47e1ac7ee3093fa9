"""Tensors an agent passes as JSON, and a model's outputs back as JSON: every count checked
against the shape before anything is allocated, numbers only, outputs clipped."""

from __future__ import annotations

from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.operations.api import Json
from oricf.logs import quoted
from oricf.models.tensors import datatype, datatype_of

MAX_TENSORS = 8
MAX_TENSOR_ELEMENTS = 1_000_000
MAX_OUTPUT_ELEMENTS = 10_000


def tensor_inputs(tensors: Any) -> dict[str, np.ndarray]:
    """{"x": {"datatype": "FP32", "shape": [1, 3], "data": [...]}} -> arrays, every count
    checked before anything is allocated."""
    if not isinstance(tensors, dict) or not tensors or len(tensors) > MAX_TENSORS:
        raise InvalidInput(f"tensors: an object of 1 to {MAX_TENSORS} named tensors")
    arrays = {}
    for name, tensor in tensors.items():
        if not isinstance(tensor, dict) or set(tensor) != {"datatype", "shape", "data"}:
            raise InvalidInput(f"tensor {quoted(name, 50)}: give datatype, shape and data")
        shape, data = tensor["shape"], tensor["data"]
        if not isinstance(shape, list) or not all(
                isinstance(d, int) and not isinstance(d, bool) and d > 0 for d in shape) \
                or len(shape) > 8:
            raise InvalidInput(f"tensor {quoted(name, 50)}: shape is up to 8 positive sizes")
        count = int(np.prod(shape, dtype=np.int64))
        if count > MAX_TENSOR_ELEMENTS or not isinstance(data, list) or len(data) != count:
            raise InvalidInput(f"tensor {quoted(name, 50)}: data must be a flat list of the "
                               f"shape's {count:,} elements (at most "
                               f"{MAX_TENSOR_ELEMENTS:,})")
        kind = datatype(str(tensor["datatype"]))
        if kind.name == "BYTES" or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in data):
            raise InvalidInput(f"tensor {quoted(name, 50)}: numbers only")
        try:
            arrays[str(name)] = np.asarray(data, dtype=kind.numpy).reshape(shape)
        except (OverflowError, ValueError) as exc:
            raise InvalidInput(f"tensor {quoted(name, 50)}: {exc}") from None
    return arrays


def tensor_json(array: np.ndarray) -> Json:
    flat = array.reshape(-1)
    out: Json = {"datatype": datatype_of(array).name, "shape": list(array.shape)}
    if flat.dtype.kind in "OSU":
        out["data"] = [str(v)[:200] for v in flat[:MAX_OUTPUT_ELEMENTS]]
    else:
        out["data"] = [round(float(v), 6) for v in flat[:MAX_OUTPUT_ELEMENTS]]
    if flat.size > MAX_OUTPUT_ELEMENTS:
        out["truncated"] = f"the first {MAX_OUTPUT_ELEMENTS:,} of {flat.size:,} elements"
    return out
