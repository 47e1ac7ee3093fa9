"""A policy that sees, small enough to check by hand: the action is each colour channel's mean
over the camera's image (after the declared resize, RGB order and 0-1 scale), then the state
as it came. A red image answers [1, 0, 0, ...state], so a test sees that the image reached
the model, in the declared colour order and scale, beside the state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from oricf.models.mlp_source import model_bytes

STATE = 2
SIZE = 8  # the network's image is SIZE x SIZE
CAMERA = "top"


def channel_means_model() -> bytes:
    from onnx import TensorProto, helper

    means = helper.make_node("ReduceMean", ["image"], ["means"], axes=[2, 3], keepdims=0)
    action = helper.make_node("Concat", ["means", "state"], ["action"], axis=1)
    graph = helper.make_graph(
        [means, action], "channel-means",
        [helper.make_tensor_value_info("state", TensorProto.FLOAT, ["batch", STATE]),
         helper.make_tensor_value_info("image", TensorProto.FLOAT,
                                       ["batch", 3, SIZE, SIZE])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", 3 + STATE])])
    return model_bytes(graph)


def declaration(folder: Path, **task: object) -> Path:
    """policy.yaml and its model in `folder`; `task` replaces keys of the task."""
    (folder / "channel-means.onnx").write_bytes(channel_means_model())
    data = {
        "name": "channel-means",
        "weights": {"path": "./channel-means.onnx"},
        "backend": {"engine": "onnxruntime", "threads": 1},
        "task": {"kind": "policy", "state": {"input": "state", "size": STATE},
                 "images": [{"name": CAMERA, "input": "image", "size": [SIZE, SIZE],
                             "resize": "stretch", "color": "rgb",
                             "scale": 1 / 255}],
                 "action": {"output": "action", "dim": 3 + STATE, "low": -10.0,
                            "high": 10.0},
                 "chunk": 1, "rate_hz": 50, **task}}
    path = folder / "policy.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def committed_declaration(folder: Path, steps: int = 3) -> Path:
    """A policy that takes the committed actions: its action is the one committed for the
    observation's own step (the window's first row) plus the state."""
    from onnx import TensorProto, helper, numpy_helper

    nodes = [helper.make_node("Slice", ["committed", "zero", "two", "one"], ["first"]),
             helper.make_node("Add", ["first", "state"], ["action"])]
    constants = [numpy_helper.from_array(np.array([v], np.int64), n)
                 for v, n in ((0, "zero"), (2, "two"), (1, "one"))]
    graph = helper.make_graph(
        nodes, "committed-first",
        [helper.make_tensor_value_info("state", TensorProto.FLOAT, ["batch", STATE]),
         helper.make_tensor_value_info("committed", TensorProto.FLOAT, ["batch", steps * 2])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", 2])], constants)
    (folder / "committed-first.onnx").write_bytes(model_bytes(graph))
    data = {"name": "committed-first", "weights": {"path": "./committed-first.onnx"},
            "backend": {"engine": "onnxruntime", "threads": 1},
            "task": {"kind": "policy", "state": {"input": "state", "size": STATE},
                     "committed": {"input": "committed", "steps": steps},
                     "action": {"output": "action", "dim": 2, "low": -10.0, "high": 10.0},
                     "chunk": 1, "rate_hz": 50}}
    path = folder / "committed.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
