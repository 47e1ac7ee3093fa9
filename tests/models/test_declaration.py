"""Model declarations: every mistake names the file and the key; weights are checked before
anything loads; a back end that is not there is refused at start."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from oricf.config import REPO_ROOT
from oricf.errors import ConfigError
from oricf.models.declaration import load_declaration
from oricf.models.declared import DeclaredModel
from oricf.store import ModelStore

YOLOX = REPO_ROOT / "configs" / "models" / "yolox-nano.yaml"


def declared(tmp_path: Path, change: dict[str, object], base: Path = YOLOX) -> Path:
    data = yaml.safe_load(base.read_text())
    data["task"]["labels_file"] = str(REPO_ROOT / "configs/models/labels/coco80.txt")
    for key, value in change.items():
        target = data
        *parents, last = key.split(".")
        for parent in parents:
            target = target.setdefault(parent, {})
        if value is None:
            target.pop(last, None)
        else:
            target[last] = value
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_every_shipped_declaration_validates() -> None:
    paths = sorted((REPO_ROOT / "configs" / "models").glob("*.yaml"))
    assert paths
    for path in paths:
        declaration = load_declaration(path)
        assert declaration.weights is not None and declaration.task is not None
        assert declaration.task.label_list(), path


BAD = [
    ({"backend": {"engine": "tensorrt"}},
     "backend.engine: 'tensorrt' is not one of onnxruntime, openvino"),
    ({"backend": {"engine": "openvino", "providers": ["CPU"]}},
     "backend.openvino.providers: unknown key"),
    ({"weights": {"catalog": "yolox-nano", "path": "x.onnx"}},
     "weights: give exactly one of catalog or path"),
    ({"weights": {"path": "x.onnx", "sha256": "abc"}}, "weights.sha256: String should match"),
    ({"task.decoder": "yolo5"}, "task.detection.decoder: Input should be 'yolox', 'yolov8'"),
    ({"task.kind": "segmentation"},
     "task.kind: 'segmentation' is not one of detection, classification"),
    ({"task.image.std": [1, 0, 1]}, "task.detection.image: std: every value must be > 0"),
    ({"task.image.layout": "chw"}, "task.detection.image.layout"),
    ({"task.labels": ["a"]}, "give one of labels or labels_file, not both"),
    ({"name": "my model!"}, "name: String should match pattern"),
    ({"task.top_k": 5}, "task.detection.top_k: unknown key"),
]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_mistakes_name_the_file_and_the_key(tmp_path: Path, change: dict[str, object],
                                            message: str) -> None:
    path = declared(tmp_path, change)
    with pytest.raises(ConfigError) as error:
        load_declaration(path)
    assert str(path) in str(error.value) and message in str(error.value)


def test_local_weights_are_checked_by_sha256_before_loading(tmp_path: Path) -> None:
    model = tmp_path / "mine.onnx"
    model.write_bytes(ModelStore().path("yolox-nano").read_bytes())
    path = declared(tmp_path, {"weights": {"path": "mine.onnx", "sha256": "0" * 64}})
    with pytest.raises(ConfigError, match=r"mine\.onnx has sha256 615e2661"):
        DeclaredModel(load_declaration(path), ModelStore()).load()
    good = declared(tmp_path, {"weights": {
        "path": "mine.onnx",
        "sha256": "615e266100c341c28d62abe255f7a6d9d7e2b91c1b0b87fc24c5d9e53141a57b"}})
    loaded = DeclaredModel(load_declaration(good), ModelStore())
    loaded.load()
    assert [s.name for s in loaded.inputs] == ["images"]


def test_missing_weights_file_and_labels_file_are_named(tmp_path: Path) -> None:
    path = declared(tmp_path, {"weights": {"path": "absent.onnx"}})
    with pytest.raises(ConfigError, match=r"weights\.path: no file .*absent\.onnx"):
        DeclaredModel(load_declaration(path), ModelStore()).load()
    path = declared(tmp_path, {"task.labels_file": "nowhere.txt"})
    with pytest.raises(ConfigError, match=r"nowhere\.txt: cannot read labels"):
        load_declaration(path).task.label_list()  # type: ignore[union-attr]


def test_an_unavailable_execution_provider_alone_is_refused_at_load(tmp_path: Path) -> None:
    path = declared(tmp_path, {"backend": {"engine": "onnxruntime",
                                           "providers": ["TensorrtExecutionProvider"]}})
    with pytest.raises(ConfigError,
                       match="none of TensorrtExecutionProvider is in this onnxruntime build"):
        DeclaredModel(load_declaration(path), ModelStore()).load()


def test_overrides_rename_tensors_and_must_fit_the_file(tmp_path: Path) -> None:
    path = declared(tmp_path, {"inputs": [{"name": "pixels"}], "task.image.input": "pixels",
                               "outputs": [{"name": "rows", "shape": [-1, 3549, 85]}],
                               "task.output": "rows"})
    model = DeclaredModel(load_declaration(path), ModelStore())
    model.load()
    assert [(s.name, s.shape) for s in model.outputs] == [("rows", (-1, 3549, 85))]
    assert model.head is not None and model.head.input_name == "pixels"
    bad = declared(tmp_path, {"inputs": [{"name": "a"}, {"name": "b"}]})
    with pytest.raises(ConfigError, match="inputs: 2 given, the model file has 1"):
        DeclaredModel(load_declaration(bad), ModelStore()).load()
    bad = declared(tmp_path, {"inputs": [{"name": "images", "datatype": "UINT8"}]})
    with pytest.raises(ConfigError, match=r"inputs\[0\].datatype: the model file says FP32"):
        DeclaredModel(load_declaration(bad), ModelStore()).load()


def test_openvino_serves_the_same_model_within_tolerance(tmp_path: Path) -> None:
    import cv2

    from tests.support.data import image

    onnx = DeclaredModel(load_declaration(YOLOX), ModelStore())
    openvino = DeclaredModel(load_declaration(declared(tmp_path, {
        "backend": {"engine": "openvino", "threads": 1}})), ModelStore())
    onnx.load()
    openvino.load()
    assert openvino.info().runtime.startswith("openvino")
    prepared = onnx.prepare(cv2.imread(str(image("person.jpg"))))
    expected, got = onnx.infer(prepared.feeds), openvino.infer(prepared.feeds)
    assert float(abs(expected["output"] - got["output"]).max()) < 1e-3
    assert len(openvino.detect(prepared, 0.35).scores) == len(onnx.detect(prepared, 0.35).scores)


def test_openvino_streams_run_concurrent_calls_side_by_side_with_the_same_answers(
        tmp_path: Path) -> None:
    """Several callers at once (a service's threads), each with an infer request of its own:
    each gets its own image's answer; OpenVINO runs two streams of one thread each."""
    import threading

    import cv2

    from tests.support.data import image

    model = DeclaredModel(load_declaration(declared(tmp_path, {
        "backend": {"engine": "openvino", "threads": 1, "streams": 2}})), ModelStore())
    model.load()
    photos = [model.prepare(cv2.imread(str(image(f)))) for f in ("person.jpg", "horses.jpg")]
    alone = [model.infer(p.feeds)["output"] for p in photos]
    assert float(abs(alone[0] - alone[1]).max()) > 0.1  # the two answers differ
    compiled = model._session._compiled  # type: ignore[union-attr]
    assert int(compiled.get_property("NUM_STREAMS")) == 2
    assert int(compiled.get_property("INFERENCE_NUM_THREADS")) == 2
    answers: dict[int, list] = {i: [] for i in range(4)}

    def caller(i: int) -> None:
        for _ in range(5):
            answers[i].append(model.infer(photos[i % 2].feeds)["output"])

    threads = [threading.Thread(target=caller, args=(i,)) for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    for i, outputs in answers.items():
        assert len(outputs) == 5
        for output in outputs:
            assert float(abs(output - alone[i % 2]).max()) < 1e-4


def test_an_unavailable_openvino_device_is_refused_at_load(tmp_path: Path) -> None:
    path = declared(tmp_path, {"backend": {"engine": "openvino", "device": "NPU"}})
    with pytest.raises(ConfigError, match=r"backend\.device: NPU is not available"):
        DeclaredModel(load_declaration(path), ModelStore()).load()


def test_a_back_end_that_is_not_installed_is_refused_naming_the_extra(tmp_path: Path) -> None:
    import subprocess
    import sys

    path = declared(tmp_path, {"backend": {"engine": "openvino"}})
    script = ("import sys; sys.modules['openvino'] = None\n"  # as if it were not installed
              "from oricf.models.declaration import load_declaration\n"
              "from oricf.models.declared import DeclaredModel\n"
              "from oricf.store import ModelStore\n"
              f"DeclaredModel(load_declaration({str(path)!r}), ModelStore()).load()\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=60, check=False)
    assert result.returncode != 0
    assert "backend.engine openvino: the openvino package is not installed " \
           "(pip install 'oricf[openvino]')" in result.stderr


def test_a_decoder_that_does_not_fit_the_model_is_refused_at_load(tmp_path: Path) -> None:
    path = declared(tmp_path, {"task.decoder": "ssd"})
    with pytest.raises(ConfigError, match=r"model yolox-nano: task: ssd decoder: output shape"):
        DeclaredModel(load_declaration(path), ModelStore()).load()
    path = declared(tmp_path, {"task.labels_file": None, "task.labels": ["a", "b"]})
    with pytest.raises(ConfigError, match="yolox decoder"):
        DeclaredModel(load_declaration(path), ModelStore()).load()


def test_an_image_input_the_model_lacks_or_cannot_take_is_refused_at_load(
        tmp_path: Path) -> None:
    path = declared(tmp_path, {"task.image.input": "pixels"})
    with pytest.raises(ConfigError, match=r"task\.image\.input: the model has no input 'pixels'"):
        DeclaredModel(load_declaration(path), ModelStore()).load()
    path = declared(tmp_path, {"task.image.datatype": "UINT8"})
    with pytest.raises(ConfigError, match="task: input 'images': datatype UINT8"):
        DeclaredModel(load_declaration(path), ModelStore()).load()


def test_the_typed_detector_refuses_a_model_that_is_not_a_detector() -> None:
    from oricf.services.detector.service import Detector
    from oricf.services.local import service_config

    config = service_config("detector", {"model": str(REPO_ROOT / "configs/models/"
                                                      "text-direction.yaml")})
    with pytest.raises(ConfigError, match=r"task\.kind: the detector serves detection models"):
        Detector(config, ModelStore())
