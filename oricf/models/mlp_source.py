"""An MLP policy whose weights are numpy array literals in a Python file, turned into ONNX.

pybullet's wheel ships its trained locomotion policies that way
(`pybullet_envs/examples/enjoy_TF_<Env>_2017may.py`: `weights_dense1_w = np.array([...])`,
obs -> 128 -> 64 -> action with ReLU). The file is parsed, never run: `ast` finds the
module-level assignments of the six arrays and `ast.literal_eval` reads each literal, so
nothing in the file is executed, imported or evaluated beyond numbers and lists. The graph
is MatMul/Add/Relu with a free batch dimension; the result is cached beside the verified
source, named by the source's sha256, so it is made once (each process under a
temporary name of its own: two services converting the same file at once both succeed).
"""

from __future__ import annotations

import ast
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from oricf.errors import ConfigError
from oricf.files import write_atomically

log = logging.getLogger(__name__)

# (weights, bias) per layer, in order; ReLU after every layer but the last.
LAYERS = (("weights_dense1_w", "weights_dense1_b"), ("weights_dense2_w", "weights_dense2_b"),
          ("weights_final_w", "weights_final_b"))
NAMES = frozenset(name for layer in LAYERS for name in layer)
INPUT = "observation"
OUTPUT = "action"
MAX_SOURCE_BYTES = 16 << 20  # the largest shipped file (Humanoid) is 0.5 MB


def read_arrays(path: Path) -> dict[str, np.ndarray]:
    """The six weight arrays of the file, as float32; errors name the file and the array."""
    if path.stat().st_size > MAX_SOURCE_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_SOURCE_BYTES >> 20} MB: not a weights file")
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    except (SyntaxError, UnicodeDecodeError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot be parsed as Python: {exc}") from None
    arrays: dict[str, np.ndarray] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 \
                and isinstance(node.targets[0], ast.Name) and node.targets[0].id in NAMES:
            name = node.targets[0].id
            arrays[name] = _literal_array(path, name, node.value)
    missing = sorted(NAMES - set(arrays))
    if missing:
        raise ConfigError(f"{path}: no array {', '.join(missing)} (an MLP policy file assigns "
                          f"{', '.join(sorted(NAMES))})")
    return arrays


def _literal_array(path: Path, name: str, value: ast.expr) -> np.ndarray:
    """`np.array(LITERAL)` (or a bare literal): the literal only, read as data."""
    if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) \
            and value.func.attr == "array" and len(value.args) == 1 and not value.keywords:
        value = value.args[0]
    try:
        data = ast.literal_eval(value)
        array = np.asarray(data, dtype=np.float32)
    except (ValueError, TypeError, SyntaxError, RecursionError) as exc:
        raise ConfigError(f"{path}: {name}: not a numeric array literal ({exc})") from None
    if not np.all(np.isfinite(array)):
        raise ConfigError(f"{path}: {name}: holds NaN or infinity")
    return array


def check_chain(path: Path, arrays: dict[str, np.ndarray]) -> tuple[int, int]:
    """Each layer's weights [in, out] and bias [out], each layer's in the last's out:
    (observation size, action size)."""
    width: int | None = None
    for w_name, b_name in LAYERS:
        w, b = arrays[w_name], arrays[b_name]
        if w.ndim != 2:
            raise ConfigError(f"{path}: {w_name}: shape {list(w.shape)}, not [in, out]")
        if b.shape != (w.shape[1],):
            raise ConfigError(f"{path}: {b_name}: shape {list(b.shape)}, {w_name} needs "
                              f"[{w.shape[1]}]")
        if width is not None and w.shape[0] != width:
            raise ConfigError(f"{path}: {w_name}: takes {w.shape[0]} values, the layer "
                              f"before gives {width}")
        width = w.shape[1]
    first = arrays[LAYERS[0][0]]
    return int(first.shape[0]), int(arrays[LAYERS[-1][0]].shape[1])


def to_onnx(arrays: dict[str, np.ndarray], sizes: tuple[int, int], name: str) -> bytes:
    """observation [batch, obs] -> action [batch, act]: MatMul, Add, Relu."""
    from onnx import TensorProto, helper

    nodes, inits = dense_layers([(arrays[w], arrays[b]) for w, b in LAYERS], INPUT, OUTPUT,
                                LAYERS)
    graph = helper.make_graph(
        nodes, name, [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT,
                                                    ["batch", sizes[0]])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["batch", sizes[1]])],
        initializer=inits)
    return model_bytes(graph)


def dense_layers(layers: Sequence[tuple[np.ndarray, np.ndarray]], x: str, output: str,
                 names: Sequence[tuple[str, str]] | None = None) -> tuple[list[Any], list[Any]]:
    """An MLP's ONNX nodes and initializers: MatMul and Add per (weights [in, out], bias
    [out]) layer, Relu between them, from the tensor `x` to `output`; `names`: each layer's
    (weights, bias) initializer names (default w0, b0, ...)."""
    from onnx import helper, numpy_helper

    names = names or [(f"w{i}", f"b{i}") for i in range(len(layers))]
    nodes, inits = [], []
    for i, ((weights, bias), (w_name, b_name)) in enumerate(zip(layers, names, strict=True)):
        inits += [numpy_helper.from_array(weights, w_name),
                  numpy_helper.from_array(bias, b_name)]
        last = i == len(layers) - 1
        nodes += [helper.make_node("MatMul", [x, w_name], [f"matmul{i}"]),
                  helper.make_node("Add", [f"matmul{i}", b_name],
                                   [output if last else f"dense{i}"])]
        if not last:
            nodes.append(helper.make_node("Relu", [f"dense{i}"], [f"relu{i}"]))
            x = f"relu{i}"
    return nodes, inits


def model_bytes(graph: Any) -> bytes:
    """The graph as a checked ONNX model (opset 13, IR 8: readable by every onnxruntime
    since 1.10)."""
    import onnx
    from onnx import helper

    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)],
                              producer_name="oricf")
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model.SerializeToString()


def converted(source: Path, sha256: str, key: str) -> Path:
    """The ONNX model of the verified source file (sha256), made once beside it; key names
    the source (the catalog entry) in errors."""
    target = source.with_name(f"{sha256}.onnx")
    if target.is_file():
        return target
    try:
        arrays = read_arrays(source)
        sizes = check_chain(source, arrays)
    except ConfigError as exc:
        raise ConfigError(f"weights {key}: {exc}") from None
    try:
        write_atomically(target, to_onnx(arrays, sizes, key))
    except OSError as exc:
        raise ConfigError(f"weights {key}: cannot write {target}: {exc.strerror}") from None
    log.info("%s: converted to %s (observation %d, action %d)", key, target.name, *sizes)
    return target
