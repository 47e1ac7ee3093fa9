"""A declared model (configs/models/*.yaml): weights, back end, tensors and task, as data.

    name: yolox-nano
    weights: {catalog: yolox-nano}            # or {path: ./my-model.onnx, sha256: ...}
    backend: {engine: onnxruntime, threads: 1} # or {engine: openvino, device: CPU}
    task:                                     # optional: raw tensors in and out without it
      kind: detection                         # or classification, or policy (policy_task)
      image: {size: [416, 416], resize: letterbox, pad_value: 114, color: bgr}
      decoder: yolox                          # yolox | yolov8 | ssd
      labels_file: labels/coco80.txt
      nms: {iou: 0.45}

Tensor names, datatypes and shapes are read from the model file; `inputs:` and `outputs:`
override them (a free dimension, or a name the file lacks). Relative paths resolve against
the declaration's folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, PrivateAttr, model_validator

from oricf.config import FilePath, Schema, load_config
from oricf.errors import ConfigError
from oricf.models.image_input import ImageInput
from oricf.models.policy_task import PolicyTask
from oricf.models.tensors import DATATYPE_NAMES

MODEL_NAME = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$"


class Weights(Schema):
    """Where the model file comes from: the catalog (sha256-checked) or a local file."""

    catalog: str | None = Field(None, description="an entry of configs/models.yaml")
    file: str | None = Field(None, description="catalog: which of the entry's files")
    path: FilePath | None = Field(None, description="a local model file")
    sha256: str | None = Field(None, pattern=r"^[0-9a-f]{64}$",
                               description="path: checked before loading when given")
    convert: Literal["mlp-arrays"] | None = Field(
        None, description="the file is not a model but its weights: mlp-arrays, an MLP's "
                          "numpy array literals in a Python file (read, never run), made "
                          "into ONNX once (oricf.models.mlp_source)")

    @model_validator(mode="after")
    def _one_source(self) -> Weights:
        if (self.catalog is None) == (self.path is None):
            raise ValueError("give exactly one of catalog or path")
        if self.path is not None and self.file is not None:
            raise ValueError("file: only with catalog")
        if self.catalog is not None and self.sha256 is not None:
            raise ValueError("sha256: only with path (the catalog has its own)")
        return self


class OnnxRuntimeBackend(Schema):
    engine: Literal["onnxruntime"]
    providers: list[str] = Field(
        default_factory=lambda: ["CPUExecutionProvider"], min_length=1,
        description="in order of preference: those this onnxruntime build lacks, or that "
                    "cannot start here, are passed over, and one log line names the one "
                    "that runs (e.g. [TensorrtExecutionProvider, CUDAExecutionProvider, "
                    "CPUExecutionProvider])")
    provider_options: dict[str, dict[str, str | int | float | bool]] = Field(
        default_factory=dict,
        description="per provider, its onnxruntime options (e.g. TensorrtExecutionProvider: "
                    "{trt_fp16_enable: true, trt_engine_cache_enable: true, "
                    "trt_engine_cache_path: /var/cache/oricf/trt})")
    threads: int = Field(1, ge=1, le=64, description="intra-op threads")
    spin: bool = Field(False, description="idle threads busy-wait: lower latency, far more CPU")


    @model_validator(mode="after")
    def _options_for_listed(self) -> OnnxRuntimeBackend:
        unlisted = sorted(set(self.provider_options) - set(self.providers))
        if unlisted:
            raise ValueError(f"provider_options: {', '.join(unlisted)} is not in providers")
        return self


class OpenVinoBackend(Schema):
    engine: Literal["openvino"]
    device: str = Field("CPU", description="OpenVINO device: CPU, GPU, NPU, AUTO")
    threads: int = Field(1, ge=1, le=64, description="inference threads (CPU), per stream")
    streams: int = Field(1, ge=1, le=64, description="inferences that run at once (CPU): "
                                                     "calls beyond them wait")
    precision: Literal["f32", "bf16", "f16"] = Field(
        "f32", description="inference precision: f32 agrees with onnxruntime; bf16 (the CPU "
                           "default where it has bfloat16 instructions) is faster but coarser")


Backend = Annotated[OnnxRuntimeBackend | OpenVinoBackend, Field(discriminator="engine")]


class TensorOverride(Schema):
    name: str
    datatype: Literal[DATATYPE_NAMES] | None = None  # type: ignore[valid-type]
    shape: list[int] | None = Field(None, description="-1 for a free dimension")


class Labels(Schema):
    labels: list[str] | None = Field(None, description="class names in class-id order")
    labels_file: FilePath | None = Field(None, description="one class name per line")

    @model_validator(mode="after")
    def _labels(self) -> Labels:
        if self.labels is not None and self.labels_file is not None:
            raise ValueError("give one of labels or labels_file, not both")
        return self

    def label_list(self) -> list[str]:
        if self.labels_file is None:
            return list(self.labels or [])
        try:
            lines = self.labels_file.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise ConfigError(f"{self.labels_file}: cannot read labels: {exc.strerror}") from None
        return [line.strip() for line in lines if line.strip()]


class Nms(Schema):
    iou: float = Field(0.45, gt=0, le=1)
    max_detections: int = Field(300, ge=1, le=100_000)


class DetectionTask(Labels):
    kind: Literal["detection"]
    image: ImageInput = ImageInput()
    decoder: Literal["yolox", "yolov8", "ssd"]
    output: str | None = Field(None, description="the output the decoder reads (default: first)")
    strides: list[int] = Field([8, 16, 32], min_length=1, description="yolox: grid strides")
    min_score: float = Field(0.35, gt=0, le=1, description="default minimum score")
    nms: Nms = Nms()

    @model_validator(mode="after")
    def _has_labels(self) -> DetectionTask:
        if self.labels is None and self.labels_file is None:
            raise ValueError("labels or labels_file: the class names, in class-id order")
        return self


class ClassificationTask(Labels):
    kind: Literal["classification"]
    image: ImageInput = ImageInput()
    output: str | None = Field(None, description="the scores output (default: first)")
    softmax: bool = Field(True, description="false when the model outputs probabilities")
    top_k: int = Field(5, ge=1, le=1000)


Task = Annotated[DetectionTask | ClassificationTask | PolicyTask, Field(discriminator="kind")]
ImageTask = DetectionTask | ClassificationTask


class ModelDeclaration(Schema):
    name: str = Field(pattern=MODEL_NAME, description="the name clients call it by")
    description: str = ""
    license: str = Field("", description="path weights: their licence (catalog: its own)")
    weights: Weights | None = Field(
        None, description="needed to serve the model; a gateway calling it needs only the task")
    backend: Backend = OnnxRuntimeBackend(engine="onnxruntime")
    inputs: list[TensorOverride] = Field(default_factory=list)
    outputs: list[TensorOverride] = Field(default_factory=list)
    task: Task | None = None
    _source: str = PrivateAttr("")  # the file it was read from, for errors found at load

    @property
    def source(self) -> str:
        """Where later errors point: the declaration's file, else the model's name."""
        return self._source or f"model {self.name}"


def load_declaration(path: Path | str) -> ModelDeclaration:
    """One model declaration file, validated; errors name the file and the key."""
    declaration = load_config(path, ModelDeclaration)
    declaration._source = str(path)
    return declaration
