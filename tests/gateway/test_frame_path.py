"""A camera frame's path, from its arrival to its published count, through parts a reader and
a type checker can follow: the camera receiver hands the frame to the pipeline
(Pipeline.handle_here), whose worker hands it to its route (Route.process), the route calls
its method (MethodCall.execute), runs its post steps (PostSteps.run, then each step's own
class, Count.run), sends its outputs to the pipeline's emitter (Emitter.emit: the outlets,
whose topic sink emits to the ROS node's publishers) and shows the record to its watchers
(Watcher.show). No module on the path finds a method by name (getattr) or keeps a function in
a field."""

from __future__ import annotations

import ast
import importlib.util
import inspect
import traceback
from pathlib import Path
from typing import Any

import pytest

from oricf.errors import InvalidInput
from oricf.gateway.components import STEPS, Emitter, PostSteps, Step
from oricf.gateway.config import OutputConfig, PostStep
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame, Record
from tests.gateway.test_pipeline import pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService

FRAME_PATH = [
    "oricf.gateway.ros.camera", "oricf.gateway.pipeline", "oricf.gateway.worker",
    "oricf.gateway.route", "oricf.gateway.components", "oricf.gateway.outlets",
    "oricf.gateway.sinks.topic", "oricf.gateway.ros.publishers", "oricf.gateway.items",
]


def source(module: str) -> ast.Module:
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.origin is not None
    return ast.parse(Path(spec.origin).read_text(), spec.origin)


def test_no_module_on_the_path_finds_a_method_by_name() -> None:
    """`getattr(x, "speaking")`, `hasattr(x, "close")`: a protocol nobody declared."""
    found = [f"{module}:{node.lineno}" for module in FRAME_PATH
             for node in ast.walk(source(module))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
             and node.func.id in ("getattr", "hasattr") and len(node.args) >= 2
             and isinstance(node.args[1], ast.Constant)]
    assert found == []


def test_no_class_on_the_path_keeps_a_function_in_a_field() -> None:
    """A field typed Callable (a closure passed in, `_emit`, `_post`, `_run_here`) is a call a
    reader cannot follow; the parts are objects with named methods instead."""
    found = []
    for module in FRAME_PATH:
        for cls in (n for n in ast.walk(source(module)) if isinstance(n, ast.ClassDef)):
            for init in (n for n in cls.body
                         if isinstance(n, ast.FunctionDef) and n.name == "__init__"):
                found += [f"{module}.{cls.name}({arg.arg})" for arg in init.args.args
                          if arg.annotation is not None
                          and "Callable" in ast.unparse(arg.annotation)]
    assert found == []


def test_every_post_step_is_a_class_with_run() -> None:
    """A post step is a Step subclass whose `run` is its own method, not a closure `build`
    returned into a field."""
    for kind in STEPS.values():
        assert isinstance(kind.step, type) and issubclass(kind.step, Step), kind.key
        assert kind.step.run.__qualname__ == f"{kind.step.__name__}.run", kind.key
        assert not inspect.isabstract(kind.step), kind.key


@pytest.mark.parametrize(("post", "record", "where"), [
    ({"count": {}}, {}, "Count.run"),
    ({"round": {"field": "speed"}}, {"speed": "fast"}, "Round.run"),
    ({"track": {}}, {"detections": None}, "Track.run"),
])
def test_a_failing_post_step_is_named_by_its_class_in_the_traceback(
        post: dict[str, Any], record: Record, where: str) -> None:
    steps = PostSteps([PostStep.model_validate(post)])
    with pytest.raises((KeyError, TypeError, InvalidInput)) as raised:
        steps.run(record)
    frames = [frame.f_code.co_qualname for frame, _ in traceback.walk_tb(raised.tb)]
    assert frames[1:3] == ["PostSteps.run", where]


class Published(Emitter):
    def __init__(self) -> None:
        self.sent: list[tuple[str, Any]] = []

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.sent.append((str(output.topic), value))


class Shown:
    def __init__(self) -> None:
        self.records: list[tuple[str, Record]] = []

    def show(self, route: str, record: Record) -> None:
        self.records.append((route, record))


def test_a_frame_reaches_its_published_count_through_the_typed_parts(
        detector: RunningService) -> None:
    published, shown = Published(), Shown()
    pipeline = Pipeline(pipeline_config(detector.address), published)
    route = pipeline.routes["people"]
    route.watchers.append(shown)
    assert isinstance(route.post, PostSteps) and route.emitter is published
    pipeline.start(inline={"people"})
    try:
        frame = Frame.from_pixels(video_frames([400])[0])
        pipeline.handle_here("people", lambda: {"image": frame})  # as the camera thread does
    finally:
        pipeline.stop()
    counts = [value for topic, value in published.sent if topic == "/human_counter"]
    assert len(counts) == 1 and counts[0] >= 1
    assert [name for name, _ in shown.records] == ["people"]
    assert shown.records[0][1]["humans"] == counts[0]
