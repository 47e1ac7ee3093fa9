"""configs/services/detector.yaml: the server, which declared model, and its label policy."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from oricf.config import FilePath, Schema, config_dir
from oricf.imaging import MAX_PIXELS
from oricf.services.runtime import ServiceConfig
from oricf.services.runtime.batching import BatchingSettings


class DetectionSettings(Schema):
    min_score: float | None = Field(
        None, gt=0, le=1, description="default minimum score (default: the model's own)")
    labels: list[str] = Field(
        default_factory=list,
        description="labels kept when a request names none (empty: all); after label_map")
    label_map: dict[str, str] = Field(
        default_factory=dict, description="rename model labels, e.g. {person: human}")


class ImageSettings(Schema):
    max_pixels: int = Field(MAX_PIXELS, ge=1, description="refuse larger images")
    annotate_jpeg_quality: int = Field(85, ge=1, le=100)
    default_annotate_encoding: Literal["jpeg", "png", "rgb8", "bgr8"] = "jpeg"


class DetectorConfig(ServiceConfig):
    model: FilePath = Field(default_factory=lambda: config_dir() / "models" / "yolox-nano.yaml",
                            description="a declared detection model (configs/models/*.yaml)")
    detection: DetectionSettings = DetectionSettings()
    images: ImageSettings = ImageSettings()
    batching: BatchingSettings | None = Field(
        None, description="dynamic batching: requests of different callers share one "
                          "inference (off if absent; the model's batch dimension must be free)")
