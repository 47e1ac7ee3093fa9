"""configs/services/detector.yaml."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.imaging import MAX_PIXELS
from oricf.services.detector.coco import COCO_LABELS
from oricf.services.runtime import ServiceConfig


class DetectorModelSettings(Schema):
    name: str = Field("yolox-nano", description="catalog name in configs/models.yaml")
    providers: list[str] = Field(
        default_factory=lambda: ["CPUExecutionProvider"],
        description="onnxruntime execution providers in order of preference, e.g. "
                    "CUDAExecutionProvider, OpenVINOExecutionProvider, CPUExecutionProvider")
    threads: int = Field(1, ge=1, le=64, description="onnxruntime intra-op threads")
    input_size: int = Field(416, ge=32, le=2048, description="square network input, pixels")
    spin: bool = Field(
        False, description="let idle onnxruntime threads busy-wait: slightly lower latency, "
                           "but several times the CPU (and battery) per frame")

    @field_validator("input_size")
    @classmethod
    def _multiple_of_32(cls, value: int) -> int:
        if value % 32:
            raise ValueError("must be a multiple of 32 (the coarsest YOLOX stride)")
        return value


class DetectionSettings(Schema):
    min_score: float = Field(0.35, gt=0, le=1, description="default minimum score")
    nms_iou: float = Field(0.45, gt=0, le=1)
    max_detections: int = Field(300, ge=1)
    labels: list[str] = Field(
        default_factory=list,
        description="labels kept when a request names none (empty: all); after label_map")
    label_map: dict[str, str] = Field(
        default_factory=dict, description="rename model labels, e.g. {person: human}")

    @field_validator("label_map")
    @classmethod
    def _known_sources(cls, value: dict[str, str]) -> dict[str, str]:
        unknown = sorted(set(value) - set(COCO_LABELS))
        if unknown:
            raise ValueError(f"unknown COCO label(s): {', '.join(unknown)}")
        return value

    @model_validator(mode="after")
    def _known_defaults(self) -> DetectionSettings:
        known = {self.label_map.get(label, label) for label in COCO_LABELS}
        unknown = sorted(set(self.labels) - known)
        if unknown:
            raise ValueError(f"labels: unknown label(s) {', '.join(unknown)}")
        return self


class ImageSettings(Schema):
    max_pixels: int = Field(MAX_PIXELS, ge=1, description="refuse larger images")
    annotate_jpeg_quality: int = Field(85, ge=1, le=100)
    default_annotate_encoding: Literal["jpeg", "png", "rgb8", "bgr8"] = "jpeg"


class DetectorConfig(ServiceConfig):
    model: DetectorModelSettings = DetectorModelSettings()
    detection: DetectionSettings = DetectionSettings()
    images: ImageSettings = ImageSettings()
