"""configs/services/detector.yaml: the server, which declared model, and its default filter."""

from __future__ import annotations

from pydantic import Field

from oricf.config import FilePath, Schema, config_dir
from oricf.imaging import MAX_PIXELS
from oricf.services.runtime import ServiceConfig
from oricf.services.runtime.batching import BatchingSettings
from oricf.services.runtime.shared_memory import SharedMemorySettings


class DetectionSettings(Schema):
    min_score: float | None = Field(
        None, gt=0, le=1, description="default minimum score (default: the model's own)")
    labels: list[str] = Field(
        default_factory=list, description="labels kept when a request names none (empty: all)")


class ImageSettings(Schema):
    max_pixels: int = Field(MAX_PIXELS, ge=1, description="refuse larger images")


class DetectorConfig(ServiceConfig):
    model: FilePath = Field(default_factory=lambda: config_dir() / "models" / "yolox-nano.yaml",
                            description="a declared detection model (configs/models/*.yaml)")
    detection: DetectionSettings = DetectionSettings()
    images: ImageSettings = ImageSettings()
    batching: BatchingSettings | None = Field(
        None, description="dynamic batching: requests of different callers share one "
                          "inference (off if absent; the model's batch dimension must be free)")
    shared_memory: SharedMemorySettings = Field(
        default_factory=SharedMemorySettings,
        description="images in system shared memory from clients on this host")
