"""A batch dimension freed in the graph, and models run in batches: YOLOX-Nano (exported with
a batch of 1) on real video frames, and small ONNX graphs made here for the cases a real
export does not show: a Reshape that holds the batch, and a graph that mixes its items."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from oricf.config import REPO_ROOT
from oricf.errors import ConfigError
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.models.declared import DeclaredModel, FixedBatch
from oricf.store import ModelStore
from tests.support.data import video_frames

YOLOX = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"


@pytest.fixture(scope="module")
def yolox() -> Iterator[DeclaredModel]:
    model = DeclaredModel(load_declaration(YOLOX), ModelStore(), batched=True)
    model.load()
    yield model
    model.close()


def test_yolox_nano_is_exported_with_a_batch_of_one_and_served_with_any() -> None:
    path = ModelStore().path("yolox-nano", "model.onnx")
    (graph_input,) = onnx.load(str(path)).graph.input
    assert graph_input.type.tensor_type.shape.dim[0].dim_value == 1


def test_a_batch_of_frames_gives_what_each_frame_gives_alone(yolox: DeclaredModel) -> None:
    assert yolox.batchable
    frames = video_frames([0, 250, 500])
    prepared = [yolox.prepare(f) for f in frames]
    batched = yolox.infer_batch([p.feeds for p in prepared])
    for p, outputs in zip(prepared, batched, strict=True):
        alone = yolox.infer(p.feeds)
        assert outputs["output"].shape == (1, 3549, 85)
        np.testing.assert_allclose(outputs["output"], alone["output"], rtol=0, atol=1e-3)
    detected = yolox.detect_batch([(p, 0.35, None) for p in prepared])
    for p, found in zip(prepared, detected, strict=True):
        alone = yolox.detect(p, 0.35)
        assert not isinstance(found, Exception)
        assert found.class_ids.tolist() == alone.class_ids.tolist()
        np.testing.assert_allclose(found.boxes, alone.boxes, atol=1e-2)
        np.testing.assert_allclose(found.scores, alone.scores, atol=1e-4)
    assert sum(int((d.class_ids == 0).sum()) for d in detected  # type: ignore[union-attr]
               ) >= 6  # people in every frame of the street video


def test_image_dimensions_freed_in_the_graph_run_at_the_declared_size() -> None:
    small = DeclaredModel(load_declaration(YOLOX.with_name("yolox-nano-320.yaml")),
                          ModelStore(), batched=True)
    small.load()
    try:
        assert small.batchable and small.inputs[0].shape == (-1, 3, -1, -1)
        prepared = [small.prepare(f) for f in video_frames([0, 300])]
        assert prepared[0].feeds["images"].shape == (1, 3, 320, 320)
        found = small.detect_batch([(p, 0.35, np.array([0])) for p in prepared])
        # 2100 cells at 320x320 (3549 at 416); people on the street in both frames.
        assert all(len(d.scores) >= 2 for d in found)  # type: ignore[union-attr]
    finally:
        small.close()


def declare(tmp_path: Path, graph: onnx.GraphProto, free_batch: bool) -> ModelDeclaration:
    path = tmp_path / "model.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)]), path)
    inputs = [{"name": "x", "shape": [-1, 4]}] if free_batch else []
    return ModelDeclaration.model_validate(
        {"name": "tiny", "weights": {"path": str(path)}, "inputs": inputs})


def x_to_y(*nodes: onnx.NodeProto, initializers: list[TensorProto] | None = None
           ) -> onnx.GraphProto:
    """A graph from x [1, 4] to y [1, 4] (float)."""
    return helper.make_graph(
        list(nodes), "tiny", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])], initializers or [])


def reshape_through_2x2() -> onnx.GraphProto:
    """x [1, 4] -> [1, 2, 2] -> Relu -> [1, 4]: both Reshapes hold the batch as 1."""
    shapes = [numpy_helper.from_array(np.array(s, np.int64), n)
              for s, n in (([1, 2, 2], "square"), ([1, 4], "flat"))]
    return x_to_y(helper.make_node("Reshape", ["x", "square"], ["s"]),
                  helper.make_node("Relu", ["s"], ["r"]),
                  helper.make_node("Reshape", ["r", "flat"], ["y"]), initializers=shapes)


def test_reshapes_that_hold_a_batch_of_one_are_freed(tmp_path: Path) -> None:
    model = DeclaredModel(declare(tmp_path, reshape_through_2x2(), True), ModelStore(),
                          batched=True)
    model.load()
    assert model.batchable and model.inputs[0].shape == (-1, 4)
    x = np.array([[1, -2, 3, -4], [-5, 6, -7, 8], [0, 1, 0, -1]], np.float32)
    (y,) = model.infer({"x": x}).values()
    np.testing.assert_array_equal(y, np.maximum(x, 0))


def test_a_graph_that_mixes_its_batch_is_refused_at_load(tmp_path: Path) -> None:
    # y = x + sum(x): the sum over every dimension takes in the other items of a batch.
    graph = x_to_y(helper.make_node("ReduceSum", ["x"], ["total"], keepdims=1),
                   helper.make_node("Add", ["x", "total"], ["y"]))
    model = DeclaredModel(declare(tmp_path, graph, True), ModelStore())
    with pytest.raises(ConfigError, match="the graph does not batch"):
        model.load()


def test_batching_a_model_whose_batch_is_fixed_is_refused_at_load(tmp_path: Path) -> None:
    model = DeclaredModel(declare(tmp_path, reshape_through_2x2(), False), ModelStore(),
                          batched=True)
    with pytest.raises(ConfigError, match=r"batching: .*'x' \[1, 4\].*shape: \[-1"):
        model.load()


def batch_revealing(tmp_path: Path) -> ModelDeclaration:
    """y = x + the number of rows the graph ran with: a batch's size, seen from inside."""
    graph = helper.make_graph(
        [helper.make_node("Shape", ["x"], ["shape"]),
         helper.make_node("Gather", ["shape", "zero"], ["rows"], axis=0),
         helper.make_node("Cast", ["rows"], ["count"], to=TensorProto.FLOAT),
         helper.make_node("Add", ["x", "count"], ["y"])],
        "rows", [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["batch", 2])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["batch", 2])],
        [numpy_helper.from_array(np.array(0, np.int64), "zero")])
    path = tmp_path / "rows.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)]), path)
    return ModelDeclaration.model_validate({"name": "rows", "weights": {"path": str(path)}})


@pytest.mark.parametrize(("on", "runs_at"), [(True, 8), (None, 0), (False, 0)],
                         ids=["fixed", "auto on the CPU", "off"])
def test_a_fixed_batch_size_pads_every_batch_and_gives_each_item_its_own_rows(
        tmp_path: Path, on: bool | None, runs_at: int) -> None:
    model = DeclaredModel(batch_revealing(tmp_path), ModelStore(), batched=True,
                          fixed_batch=FixedBatch(8, on))
    model.load()
    assert model.pad_to == runs_at
    items = [{"x": np.array([[1.0, 2.0]], np.float32)},
             {"x": np.array([[3.0, 4.0], [5.0, 6.0]], np.float32)}]
    for batch in ([items[0]], items):
        rows = sum(len(item["x"]) for item in batch)
        outputs = model.infer_batch(batch)
        for item, output in zip(batch, outputs, strict=True):
            # the graph saw the fixed size, or the batch as it came; each item its own rows
            np.testing.assert_array_equal(output["y"], item["x"] + (runs_at or rows))
