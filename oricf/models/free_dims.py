"""Free dimensions for an ONNX file exported with fixed ones (a batch of 1, a 416x416 image).

Many exports fix every dimension: the graph's inputs and outputs say [1, 3, 416, 416], and
Reshape nodes carry shapes such as [1, 85, -1]. Where that is all, dimensions can be freed:
- the batch (axis 0): the inputs' and outputs' first dimension becomes symbolic, and a
  Reshape whose constant target shape starts with 1 gets 0 there instead ("copy this
  dimension from the input": the batch);
- any other input axis (an image's height and width): it becomes symbolic, and so does
  every output dimension but the batch, since their sizes may follow it.
Shapes that were inferred for the fixed sizes are dropped and inferred again by the runtime.

That is not proof the graph runs, or runs right: an Expand, a Tile or a computed shape may
still hold a fixed size. The model class checks at load that a batch gives what its items
give alone, and runs its declared pre- and post-processing at the declared image size, and
refuses the model otherwise.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from oricf.errors import ConfigError

log = logging.getLogger(__name__)

BATCH = "batch"


def free_dimensions(path: Path, free: Sequence[Sequence[int]]) -> bytes:
    """The model file with the given axes of its inputs freed (free[i]: the axes of its i-th
    input), as bytes for onnxruntime."""
    try:
        import onnx
    except ImportError:
        raise ConfigError(f"{path}: freeing its dimensions needs the onnx package "
                          f"(pip install onnx)") from None
    model = onnx.load(str(path))
    graph = model.graph
    constants = _constants(graph)
    inputs = [value for value in graph.input if value.name not in constants]
    batch = other = False
    for value, axes in zip(inputs, free, strict=False):
        dims = value.type.tensor_type.shape.dim
        for axis in axes:
            if axis < len(dims) and dims[axis].HasField("dim_value"):
                dims[axis].Clear()
                dims[axis].dim_param = BATCH if axis == 0 else f"{value.name}_{axis}"
                batch, other = batch or axis == 0, other or axis > 0
    for value in graph.output:
        dims = value.type.tensor_type.shape.dim
        for axis, dim in enumerate(dims):
            if (axis == 0 and batch) or (axis > 0 and other):
                dim.Clear()
                dim.dim_param = BATCH if axis == 0 else f"{value.name}_{axis}"
    del graph.value_info[:]  # inferred for the fixed sizes
    reshapes = _free_reshape_batch(graph, constants) if batch else 0
    log.info("%s: %s freed (%d Reshape shapes follow the batch)", path.name,
             " and ".join(n for n, f in (("batch", batch), ("other dimensions", other)) if f),
             reshapes)
    return bytes(model.SerializeToString())


def _constants(graph: Any) -> dict[str, Any]:
    """Initializers and Constant nodes' tensors, by name."""
    constants: dict[str, Any] = {init.name: init for init in graph.initializer}
    for node in graph.node:
        if node.op_type == "Constant" and node.attribute and node.attribute[0].name == "value":
            constants[node.output[0]] = node.attribute[0].t
    return constants


def _free_reshape_batch(graph: Any, constants: dict[str, Any]) -> int:
    """Reshapes to a constant shape starting with 1 copy the batch instead (0)."""
    from onnx import numpy_helper

    changed = 0
    for node in graph.node:
        if node.op_type != "Reshape" or node.input[1] not in constants:
            continue
        if any(a.name == "allowzero" and a.i for a in node.attribute):
            continue  # 0 would mean a zero-sized dimension there, not "copy"
        tensor = constants[node.input[1]]
        shape = numpy_helper.to_array(tensor).copy()
        if shape.ndim == 1 and len(shape) > 0 and shape[0] == 1:
            shape[0] = 0
            tensor.CopyFrom(numpy_helper.from_array(shape, tensor.name))
            changed += 1
    return changed
