"""Execution providers in the declared order: those this onnxruntime lacks are passed over,
one log line names the one that runs, and where it runs is in GetModelInfo."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from oricf.bench.common import load_frames
from oricf.config import REPO_ROOT
from oricf.errors import ConfigError
from oricf.models.declaration import load_declaration
from oricf.models.declared import DeclaredModel
from oricf.store import ModelStore
from oricf.v1 import common_pb2, detector_pb2_grpc
from tests.models.test_declaration import declared
from tests.support.services import running_service

MODELS = REPO_ROOT / "configs" / "models"
PERSON = np.array([0])


def people(model: DeclaredModel, frame: np.ndarray) -> int:
    return len(model.detect(model.prepare(frame), 0.35, PERSON).boxes)


def test_the_gpu_declaration_runs_on_the_cpu_where_there_is_no_gpu(
        caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="oricf.models.declared"):
        gpu = DeclaredModel(load_declaration(MODELS / "yolox-nano-gpu.yaml"), ModelStore())
        gpu.load()
    cpu = DeclaredModel(load_declaration(MODELS / "yolox-nano.yaml"), ModelStore())
    cpu.load()
    assert gpu.info().providers[0] == "CPUExecutionProvider"
    placed = [r.getMessage() for r in caplog.records if "gpu runs on" in r.getMessage()]
    assert placed == [
        "model yolox-nano-gpu runs on CPUExecutionProvider with onnxruntime "
        f"{gpu.info().runtime.split()[-1]} (passed over: TensorrtExecutionProvider: not in "
        "this onnxruntime build; CUDAExecutionProvider: not in this onnxruntime build)"]
    frames = load_frames(4)
    assert [people(gpu, f) for f in frames] == [people(cpu, f) for f in frames]
    assert people(cpu, frames[0]) >= 3  # the pedestrian video's first frame has people


def test_a_model_no_declared_provider_can_run_is_refused(tmp_path: Path) -> None:
    path = declared(tmp_path, {"backend": {"engine": "onnxruntime", "providers": [
        "TensorrtExecutionProvider", "CUDAExecutionProvider"]}})
    with pytest.raises(ConfigError, match="none of TensorrtExecutionProvider, "
                                          "CUDAExecutionProvider is in this onnxruntime build"):
        DeclaredModel(load_declaration(path), ModelStore()).load()


def test_options_are_for_declared_providers_only(tmp_path: Path) -> None:
    path = declared(tmp_path, {"backend": {
        "engine": "onnxruntime", "providers": ["CPUExecutionProvider"],
        "provider_options": {"CUDAExecutionProvider": {"device_id": 0}}}})
    with pytest.raises(ConfigError, match="provider_options: CUDAExecutionProvider is not in "
                                          "providers"):
        load_declaration(path)
    with pytest.raises(ConfigError, match="providers: List should have at least 1 item"):
        load_declaration(declared(tmp_path, {"backend": {"engine": "onnxruntime",
                                                         "providers": []}}))


def test_the_service_says_where_its_model_runs(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="oricf.services.runtime.server"), \
            running_service("detector", {"model": str(MODELS / "yolox-nano-gpu.yaml")}) as service:
        info = detector_pb2_grpc.DetectorStub(service.channel).GetModelInfo(
            common_pb2.GetModelInfoRequest(), timeout=10)
    assert info.model == "yolox-nano-gpu" and info.providers[0] == "CPUExecutionProvider"
    assert any(r.getMessage().endswith("runs on CPUExecutionProvider; SERVING")
               for r in caplog.records)


class FallingBackOnnxRuntime:
    """onnxruntime's own behaviour when TensorRT's libraries are missing, which only a GPU
    build shows: InferenceSession logs the error and retries on CUDA and the CPU by name,
    without the options given for them (seen with onnxruntime-gpu 1.31.1 on an H200)."""

    def __init__(self) -> None:
        self.opened: list[list[object]] = []

    def get_available_providers(self) -> list[str]:
        return ["TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider"]

    def InferenceSession(self, model: str, options: object,
                         providers: list[object]) -> object:
        names = [p if isinstance(p, str) else p[0] for p in providers]
        if names[0] == "TensorrtExecutionProvider":
            providers = ["CUDAExecutionProvider", "CPUExecutionProvider"]  # its fallback
        self.opened.append(providers)
        first = providers[0] if isinstance(providers[0], str) else providers[0][0]
        return type("Session", (), {"get_providers": lambda self: [first]})()


def test_providers_onnxruntime_falls_back_to_itself_keep_their_declared_options() -> None:
    from oricf.models.providers import open_in_order

    backend = load_declaration(MODELS / "yolox-nano-gpu.yaml").backend
    ort = FallingBackOnnxRuntime()
    _, passed_over = open_in_order(ort, "model.onnx", None, backend)  # type: ignore[arg-type]
    assert ort.opened[-1][0] == ("CUDAExecutionProvider", {"cudnn_conv_algo_search": "HEURISTIC"})
    assert passed_over == ["TensorrtExecutionProvider: did not start (onnxruntime's log says why)"]
