"""A policy that sees, small enough to check by hand: the action is each colour channel's mean
over the camera's image (after the declared resize, RGB order and 0-1 scale), then the state
as it came. A red image answers [1, 0, 0, ...state], so a test sees that the image reached
the model, in the declared colour order and scale, beside the state."""

from __future__ import annotations

from pathlib import Path

import yaml

STATE = 2
SIZE = 8  # the network's image is SIZE x SIZE
CAMERA = "top"


def model_bytes() -> bytes:
    import onnx
    from onnx import TensorProto, helper

    means = helper.make_node("ReduceMean", ["image"], ["means"], axes=[2, 3], keepdims=0)
    action = helper.make_node("Concat", ["means", "state"], ["action"], axis=1)
    graph = helper.make_graph(
        [means, action], "channel-means",
        [helper.make_tensor_value_info("state", TensorProto.FLOAT, ["batch", STATE]),
         helper.make_tensor_value_info("image", TensorProto.FLOAT,
                                       ["batch", 3, SIZE, SIZE])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", 3 + STATE])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model.SerializeToString()


def declaration(folder: Path, **task: object) -> Path:
    """policy.yaml and its model in `folder`; `task` replaces keys of the task."""
    (folder / "channel-means.onnx").write_bytes(model_bytes())
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
