"""The shared YAML loader: errors name the file and the key path."""

import re
from pathlib import Path

import pytest
import yaml
from pydantic import Field

from oricf.config import FilePath, Schema, apply_set, load_config
from oricf.errors import ConfigError


class Route(Schema):
    topic: str
    timeout_ms: int = Field(gt=0)


class Pipeline(Schema):
    name: str = "p"
    routes: list[Route] = []
    model_file: FilePath | None = None


def write(tmp_path: Path, text: str, name: str = "x.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_bad_value_names_file_and_key_path(tmp_path: Path) -> None:
    text = "routes:\n  - {topic: a, timeout_ms: 5}\n  - {topic: b, timeout_ms: 0}\n"
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_config(path, Pipeline)
    assert f"{path}: routes[1].timeout_ms: Input should be greater than 0" in str(err.value)


def test_unknown_key_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, "routes:\n  - {topic: a, timeout_ms: 5, tiemout: 3}\n")
    with pytest.raises(ConfigError, match=r"x.yaml: routes\[0\].tiemout: unknown key"):
        load_config(path, Pipeline)


def test_invalid_yaml_names_file_and_line(tmp_path: Path) -> None:
    path = write(tmp_path, "name: a\nroutes: [\n")
    with pytest.raises(ConfigError, match=r"x.yaml: invalid YAML \(line 3"):
        load_config(path, Pipeline)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.yaml: file not found"):
        load_config(tmp_path / "nope.yaml", Pipeline)


def test_relative_paths_resolve_against_the_yaml_file(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    path = write(tmp_path / "sub", "model_file: ../weights/m.onnx\n")
    config = load_config(path, Pipeline)
    assert config.model_file == tmp_path / "sub" / ".." / "weights" / "m.onnx"


def test_overlay_merges_on_top(tmp_path: Path) -> None:
    base = write(tmp_path, "name: base\nroutes: [{topic: a, timeout_ms: 5}]\n")
    overlay = write(tmp_path, "name: edge\n", "edge.yaml")
    config = load_config(base, Pipeline, overlays=[overlay])
    assert config.name == "edge"
    assert config.routes[0].topic == "a"


def test_an_overlays_relative_paths_resolve_against_the_overlay(tmp_path: Path) -> None:
    (tmp_path / "robot").mkdir()
    (tmp_path / "site").mkdir()
    base = write(tmp_path / "robot", "name: base\nmodel_file: m.onnx\n")
    renamed = write(tmp_path / "site", "name: site\n", "rename.yaml")
    assert load_config(base, Pipeline, [renamed]).model_file == tmp_path / "robot" / "m.onnx"
    moved = write(tmp_path / "site", "model_file: weights/m.onnx\n", "model.yaml")
    config = load_config(base, Pipeline, [moved, renamed])
    assert config.model_file == tmp_path / "site" / "weights" / "m.onnx"
    assert config.name == "site" and type(config.name) is str


def test_a_gateway_overlays_wav_file_resolves_against_the_overlay(tmp_path: Path) -> None:
    from oricf.gateway.config import load_pipeline

    (tmp_path / "site").mkdir()
    base = write(tmp_path, yaml.safe_dump({
        "endpoints": {"asr": {"address": "127.0.0.1:50052"}},
        "routes": {"asked": {"input": {"audio": "question.wav"},
                             "call": {"service": "asr", "method": "Transcribe"},
                             "outputs": [{"jsonl": "-", "from": "transcript"}]}}}))
    overlay = write(tmp_path / "site", yaml.safe_dump(
        {"routes": {"asked": {"input": {"audio": "recorded.wav"}}}}), "site.yaml")
    assert load_pipeline(base).routes["asked"].input.audio == str(tmp_path / "question.wav")
    placed = load_pipeline(base, [overlay]).routes["asked"].input
    assert placed.audio == str(tmp_path / "site" / "recorded.wav")


def test_set_assignments_reach_any_key_as_yaml_values() -> None:
    data = {"routes": {"people": {"input": {"url": "a.mp4"}, "outputs": [{"jsonl": "x"}]}}}
    data = apply_set(data, "routes.people.input.url=rtsp://cam.local/stream")
    data = apply_set(data, "routes.people.input.fps=5")
    data = apply_set(data, "routes.people.outputs.0.jsonl=-")
    data = apply_set(data, "routes.people.post=[{count: {}}]")
    data = apply_set(data, "endpoints.detector.address=10.0.0.2:50051")
    assert data["routes"]["people"]["input"] == {"url": "rtsp://cam.local/stream", "fps": 5}
    assert data["routes"]["people"]["outputs"] == [{"jsonl": "-"}]
    assert data["routes"]["people"]["post"] == [{"count": {}}]
    assert data["endpoints"] == {"detector": {"address": "10.0.0.2:50051"}}


@pytest.mark.parametrize(("assignment", "message"), [
    ("routes.people", "expected KEY.PATH=VALUE"),
    ("routes..url=x", "expected KEY.PATH=VALUE"),
    ("routes.people.outputs.3.jsonl=-", "'3' is not an index of a list of 1 items"),
    ("routes.people.outputs.0.jsonl.x=-", "'x' is under a value that is not a mapping"),
    ("routes.people.post=[a, b", "the value: invalid YAML"),
])
def test_bad_set_assignments_are_refused_clearly(assignment: str, message: str) -> None:
    data = {"routes": {"people": {"outputs": [{"jsonl": "x"}]}}}
    with pytest.raises(ConfigError, match=re.escape(message)):
        apply_set(data, assignment)
