"""The Infer method: a declared model's pre- and post-processing in the gateway around a real
Open Inference Protocol server (`oricf serve models`), against the typed Detect."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from oricf.config import REPO_ROOT, deep_merge
from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, parse_pipeline
from tests.gateway.test_pipeline import FRAMES, Outputs, pipeline_config, run_frames
from tests.support.processes import free_port
from tests.support.services import RunningService

YOLOX = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"


def infer_config(address: str, change: dict[str, Any] | None = None) -> PipelineConfig:
    """The people route of tests.gateway.test_pipeline with Infer instead of Detect."""
    data = {"endpoints": {"models": {"address": address}},
            "routes": {"people": {"call": {
                "service": "models", "method": "Infer", "model": str(YOLOX),
                "labels": ["person"]}}}}
    config = pipeline_config("127.0.0.1:1").model_dump(by_alias=True, exclude_unset=True)
    del config["endpoints"]["detector"]
    config["routes"]["people"]["call"] = {}
    return parse_pipeline(deep_merge(deep_merge(config, data), change or {}), "infer pipeline")


def counts(outputs: Outputs) -> list[int]:
    return [v for topic, v in outputs.sent if topic == "/human_counter"]


def test_infer_counts_exactly_as_detect_on_the_same_declaration(
        detector: RunningService, models: RunningService) -> None:
    _, by_detect = run_frames(pipeline_config(detector.address), FRAMES)
    pipeline, by_infer = run_frames(infer_config(models.address), FRAMES)
    assert counts(by_infer) == counts(by_detect) and counts(by_infer)[0] == 4
    assert by_infer.sent[1] == ("/summary", "4 people in view")
    assert pipeline.routes["people"].stats.ok == len(FRAMES)


def test_jpeg_transport_sends_encoded_frames_the_server_pre_processes(
        models: RunningService) -> None:
    jpeg = {"endpoints": {"models": {"image": {"transport": "jpeg", "jpeg_quality": 85}}}}
    _, raw = run_frames(infer_config(models.address), FRAMES)
    _, encoded = run_frames(infer_config(models.address, jpeg), FRAMES)
    assert all(abs(a - b) <= 1 for a, b in zip(counts(raw), counts(encoded), strict=True))


def test_infer_fails_over_to_the_fallback_and_deadlines_apply(models: RunningService) -> None:
    dead = f"127.0.0.1:{free_port()}"
    config = infer_config(dead, {"endpoints": {"models": {
        "fallback": models.address, "deadline_ms": 5000}}})
    pipeline, outputs = run_frames(config, FRAMES)
    assert counts(outputs)[0] == 4 and len(counts(outputs)) == len(FRAMES)
    assert pipeline.endpoints["models"].failovers == 1


def test_unknown_model_on_the_server_is_a_logged_call_error(models: RunningService) -> None:
    pipeline, outputs = run_frames(
        infer_config(models.address, {"routes": {"people": {"call": {
            "model_name": "no-such-model"}}}}), FRAMES[:1])
    assert outputs.sent == []
    assert pipeline.routes["people"].stats.errors == {"NOT_FOUND": 1}


def _declaration(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "model.yaml"
    path.write_text(text)
    return path


BAD_CALLS = [
    ({"labels": ["unicorn"]}, "labels: the model has no label(s) unicorn"),
    ({"top_k": 3}, "top_k: only for classification models"),
    ({"prompt": "{text}"}, "routes.people.call.Infer.prompt: unknown key"),
    ({"model": "/nowhere/model.yaml"},
     "infer pipeline: routes.people.call.Infer: model: /nowhere/model.yaml: file not found"),
    ({"model": str(REPO_ROOT / "configs/models/policies/hopper.yaml"), "labels": []},
     "hopper.yaml is a policy (task.kind: policy); Infer calls image models"),
]


@pytest.mark.parametrize(("change", "message"), BAD_CALLS)
def test_bad_infer_calls_are_refused_at_load(change: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        infer_config("127.0.0.1:1", {"routes": {"people": {"call": change}}})


def test_a_declaration_without_task_is_refused(tmp_path: Path) -> None:
    path = _declaration(tmp_path, "name: raw\nweights: {path: model.onnx}\n")
    with pytest.raises(ConfigError, match="declares no task"):
        infer_config("127.0.0.1:1", {"routes": {"people": {"call": {"model": str(path),
                                                                     "labels": []}}}})


def test_infer_on_a_classifier_adds_label_classes_and_score(models: RunningService) -> None:
    import cv2

    from oricf.gateway.pipeline import Pipeline
    from oricf.gateway.values import Frame
    from tests.support.data import text_crops

    data = {"endpoints": {"models": {"address": "127.0.0.1:1"}},
            "routes": {"direction": {
                "input": {"topic": "camera/text", "type": "sensor_msgs/Image"},
                "call": {"service": "models", "method": "Infer", "top_k": 1,
                         "model": str(REPO_ROOT / "configs/models/text-direction.yaml")},
                "outputs": [{"topic": "/direction", "type": "std_msgs/String",
                             "from": "label"}]}}}
    crops = text_crops()[:6]
    data["endpoints"]["models"]["address"] = models.address
    outputs = Outputs()
    pipeline = Pipeline(parse_pipeline(data, "classifier pipeline"), outputs)
    pipeline.start()
    records = []
    for crop in crops + [cv2.rotate(c, cv2.ROTATE_180) for c in crops]:
        frame = Frame.from_pixels(crop)
        records.append(pipeline.routes["direction"].run({"image": frame}))
        pipeline.submit("direction", lambda f=frame: {"image": f})
        assert pipeline.idle(10)
    pipeline.stop()
    labels = [r["label"] for r in records]
    assert labels[:6].count("0") >= 5 and labels[6:].count("180") >= 5, labels
    assert all(len(r["classes"]) == 1 and 0.5 <= r["score"] <= 1 for r in records)
    assert [v for _, v in outputs.sent] == labels
